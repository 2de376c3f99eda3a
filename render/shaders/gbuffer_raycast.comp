#version 430 core
// A G-buffer made by tracing primary rays through the grid (closest hit, clip caps): the
// lighting tests and benchmark use it where the impostor pass is not needed, and it checks
// the closest-hit traversal the path tracer uses. Row 0 is the bottom row (GL convention).
layout(local_size_x = 8, local_size_y = 8) in;

#include "grid_traversal.glsl"
#include "constants.glsl"

layout(rgba32f, binding = 0) uniform writeonly image2D u_out_position;
layout(rgba32f, binding = 1) uniform writeonly image2D u_out_normal;
layout(rg32i, binding = 2) uniform writeonly iimage2D u_out_ids;  // (atom, kind) as render/gl/targets.py

uniform mat4 u_inv_proj;
uniform mat4 u_inv_view;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(u_out_ids);
    if (px.x >= size.x || px.y >= size.y) return;
    vec2 ndc = (vec2(px) + 0.5) / vec2(size) * 2.0 - 1.0;
    vec4 near_point = u_inv_proj * vec4(ndc, -1.0, 1.0);
    vec3 eye = u_inv_view[3].xyz;
    vec3 d = normalize(mat3(u_inv_view) * (near_point.xyz / near_point.w));
    float t;
    int atom;
    vec3 normal;
    bool cap;
    if (trace_closest(eye, d, 0.0, BIG, -1, true, t, atom, normal, cap)) {
        imageStore(u_out_position, px, vec4(eye + t * d, 1.0));
        imageStore(u_out_normal, px, vec4(normalize(normal), 0.0));
        imageStore(u_out_ids, px, ivec4(atom, atom == ATOM_PROBE ? KIND_PROBE : (cap ? KIND_CAP : KIND_SPHERE), 0, 0));
    } else {
        imageStore(u_out_position, px, vec4(0.0));
        imageStore(u_out_normal, px, vec4(0.0));
        imageStore(u_out_ids, px, ivec4(ATOM_BACKGROUND, KIND_BACKGROUND, 0, 0));
    }
}
