#version 430 core
// Analytic ambient occlusion per G-buffer pixel (ao_analytic.glsl), as an r32f image.
layout(local_size_x = 8, local_size_y = 8) in;

#include "ao_analytic.glsl"

layout(r32f, binding = 0) uniform writeonly image2D u_accessibility;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_accessibility)))) return;
    imageStore(u_accessibility, px, vec4(analytic_accessibility(px)));
}
