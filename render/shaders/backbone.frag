#version 410 core
// Backbone trace into the G-buffer: a thin tube look (normal turns across the width),
// removed by the clipping planes and inside the navigation cube, where spheres show
// the atoms instead; with u_cube_window also wherever the pixel's eye ray crosses the
// cube, so no trace in front of the cube (or behind it) is drawn over its contents.
#include "camera.glsl"
#include "clip.glsl"
#include "gbuffer_out.glsl"

in LineFragment {
    vec3 position;
    vec3 color;
    float across;
    float along;
    flat vec3 tangent;
    flat ivec2 ends;
} fs_in;

uniform int u_cube_enabled;
uniform vec4 u_cube;       // centre xyz, half edge (Å)
uniform mat3 u_cube_axes;  // the cube's axes (columns) in the world frame
uniform int u_cube_window;

// Whether the ray o + t d (t >= 0) meets the cube (slabs in the cube's own frame).
bool ray_meets_cube(vec3 o, vec3 d) {
    vec3 ol = transpose(u_cube_axes) * (o - u_cube.xyz);
    vec3 dl = transpose(u_cube_axes) * d;
    float t0 = 0.0, t1 = 1e30;
    for (int a = 0; a < 3; ++a) {
        if (abs(dl[a]) < 1e-12) {
            if (abs(ol[a]) > u_cube.w) return false;
            continue;
        }
        float ta = (-u_cube.w - ol[a]) / dl[a];
        float tb = (u_cube.w - ol[a]) / dl[a];
        t0 = max(t0, min(ta, tb));
        t1 = min(t1, max(ta, tb));
    }
    return t0 <= t1;
}

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
