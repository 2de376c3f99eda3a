#version 430 core
// The occlusion atlas looked up per G-buffer pixel (atlas_lookup.glsl) over a rectangle
// (u_offset: its first pixel).
layout(local_size_x = 8, local_size_y = 8) in;

#include "atlas_lookup.glsl"

uniform ivec2 u_offset;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy) + u_offset;
    if (any(greaterThanEqual(px, imageSize(u_ambient)))) return;
    look_up(px);
}
