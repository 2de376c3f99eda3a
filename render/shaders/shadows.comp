#version 430 core
// Light visibility per G-buffer pixel (shadow_pixel.glsl), written to an r32f image. The
// pass may cover a rectangle only (u_offset: its first pixel), and only the probe's own
// pixels (u_only_probe; the others keep what they hold). shadows.frag is the same trace
// for G-buffers with a depth buffer.
layout(local_size_x = 8, local_size_y = 8) in;

#include "shadow_pixel.glsl"

layout(r32f, binding = 0) uniform writeonly image2D u_visibility;

uniform ivec2 u_offset;
uniform int u_only_probe;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy) + u_offset;
    if (any(greaterThanEqual(px, imageSize(u_visibility)))) return;
    vec3 p, n;
    int atom;
    bool lit = gbuffer_fetch(px, p, n, atom);
    if (u_only_probe != 0 && atom != ATOM_PROBE) return;
    imageStore(u_visibility, px, vec4(light_visibility(lit, p, n, atom)));
}
