#version 410 core
// One vertex per sphere; the geometry shader (quad mode) or the point size (sprite
// mode) makes the screen footprint, the fragment shader casts the ray.
in vec4 in_sphere;  // centre xyz (Å, world), radius
in vec4 in_color;   // CPK rgb, unused alpha

out VertexData {
    flat vec4 sphere;
    flat vec3 color;
    flat int id;
} vs_out;

#ifdef SPRITE
#include "camera.glsl"
#include "sphere_bound.glsl"
#endif

void main() {
    vs_out.sphere = in_sphere;
    vs_out.color = in_color.rgb;
    vs_out.id = gl_VertexID;  // with indexed drawing: the atom index itself
#ifdef SPRITE
    // Low-end option: a square point sprite around the projected quad. Points whose
    // centre leaves the view volume are clipped whole, so spheres vanish at the edges.
    vec3 corners[4];
    float ok = sphere_quad(in_sphere.xyz, in_sphere.w, corners);
    vec2 lo = vec2(1e30), hi = vec2(-1e30);
    float wmin = 1e30;
    for (int i = 0; i < 4; ++i) {
        vec4 c = u_viewproj * vec4(corners[i], 1.0);
        wmin = min(wmin, c.w);
        lo = min(lo, c.xy / c.w);
        hi = max(hi, c.xy / c.w);
    }
    vec2 size_px = (hi - lo) * 0.5 * u_viewport.zw;
    // Depth of the sphere's point nearest the camera plane: no part of it is nearer.
    vec4 front = u_viewproj * vec4(in_sphere.xyz + u_cam_basis[2] * in_sphere.w, 1.0);
    gl_Position = (ok > 0.0 && wmin > 0.0) ? vec4((lo + hi) * 0.5, front.z / front.w, 1.0) : vec4(2.0, 2.0, 2.0, 1.0);
    gl_PointSize = max(size_px.x, size_px.y) + 2.0;
#endif
}
