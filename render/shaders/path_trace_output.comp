#version 430 core
// The path tracer's running mean into the renderer's lit image (RGBA8) where it shades
// (spheres, caps, the probe), clamped as the shading pass clamps, times the edge-cueing
// factor; backbone and background pixels keep what the shading pass drew.
layout(local_size_x = 8, local_size_y = 8) in;

#include "gbuffer_input.glsl"

layout(binding = 3) uniform sampler2D u_radiance;
layout(binding = 4) uniform sampler2D u_visibility;
layout(rgba8, binding = 0) uniform writeonly image2D u_lit;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_lit))) || !gbuffer_lit(px)) return;
    vec3 color = min(texelFetch(u_radiance, px, 0).rgb, vec3(1.0)) * texelFetch(u_visibility, px, 0).a;
    imageStore(u_lit, px, vec4(color, 1.0));
}
