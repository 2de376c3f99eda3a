#version 430 core
// A layered frame's sun and ambient terms as the G-buffer export gives them
// (visibility_terms.glsl EXPORT: the probe's terms added), over a rectangle (u_offset: its
// first pixel). The frames themselves are composed by visibility_compose.frag.
layout(local_size_x = 8, local_size_y = 8) in;

#define EXPORT
#include "visibility_terms.glsl"

layout(r32f, binding = 1) uniform writeonly image2D u_sun_out;
layout(r32f, binding = 2) uniform writeonly image2D u_ambient_out;

uniform ivec2 u_offset;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy) + u_offset;
    if (any(greaterThanEqual(px, imageSize(u_sun_out)))) return;
    float sun, ambient;
    composed_visibility(px, sun, ambient);
    imageStore(u_sun_out, px, vec4(sun));
    imageStore(u_ambient_out, px, vec4(ambient));
}
