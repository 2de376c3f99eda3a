#version 410 core
// Backbone trace into the G-buffer: a thin tube look (normal turns across the width),
// removed by the clipping planes and inside the navigation cube, where spheres show
// the atoms instead; with u_cube_window also wherever the pixel's eye ray crosses the
// cube, so no trace in front of the cube (or behind it) is drawn over its contents.
#include "camera.glsl"
#include "clip.glsl"
#include "gbuffer_out.glsl"

#include "line_blocks.glsl"
in LINE_FRAGMENT_BLOCK fs_in;

#include "cube_window.glsl"
uniform int u_cube_enabled;
uniform int u_cube_window;

void main() {
    vec3 p = fs_in.position;
    if (!point_kept(p)) discard;
    if (u_cube_enabled == 1) {
        if (all(lessThanEqual(abs(transpose(u_cube_axes) * (p - u_cube.xyz)), vec3(u_cube.w)))) discard;
        if (u_cube_window == 1 && ray_meets_cube(u_eye, eye_ray(gl_FragCoord.xy))) discard;
    }
    vec3 to_eye = normalize(u_eye - p);
    vec3 side = cross(fs_in.tangent, to_eye);
    float side_len = length(side);
    vec3 n = to_eye;
    if (side_len > 1e-6) {
        side /= side_len;
        vec3 facing = normalize(cross(side, fs_in.tangent));  // perpendicular to the tube, towards the eye
        float a = clamp(fs_in.across, -1.0, 1.0);
        n = normalize(facing * sqrt(max(1.0 - a * a, 0.0)) + side * a);
    }
    int id = fs_in.along < 0.5 ? fs_in.ends.x : fs_in.ends.y;  // the nearer trace atom
    write_gbuffer(fs_in.color, p, n, id, KIND_BACKBONE);
}
