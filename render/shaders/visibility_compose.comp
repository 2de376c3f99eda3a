#version 430 core
// The visibility buffer from the lighting terms over a rectangle (visibility_terms.glsl;
// u_offset: its first pixel), for the G-buffer export: EXPORT (with LAYERED) also writes
// the sun and ambient terms with the probe's share added (r32f). The frames themselves
// are composed by visibility_compose.frag.
layout(local_size_x = 8, local_size_y = 8) in;

#include "visibility_terms.glsl"

layout(rgba32f, binding = 0) uniform writeonly image2D u_visibility;
layout(r32f, binding = 1) uniform writeonly image2D u_sun_out;
layout(r32f, binding = 2) uniform writeonly image2D u_ambient_out;

uniform ivec2 u_offset;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy) + u_offset;
    if (any(greaterThanEqual(px, imageSize(u_visibility)))) return;
    float sun, ambient;
    vec4 visibility = composed_visibility(px, sun, ambient);
#ifdef EXPORT
    imageStore(u_sun_out, px, vec4(sun));
    imageStore(u_ambient_out, px, vec4(ambient));
#endif
    imageStore(u_visibility, px, visibility);
}
