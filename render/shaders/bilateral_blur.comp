#version 430 core
// Depth- and normal-aware (bilateral) blur of a noisy accessibility image, which may be at
// half resolution (u_scale = 2): each output pixel averages source pixels around it,
// weighted by screen distance, by how close their surface's depth is to its own (relative
// to u_depth_sigma of its depth) and by normal agreement, so occlusion does not bleed
// across silhouettes. Doubles as the joint-bilateral upsampler of half-resolution SSAO.
layout(local_size_x = 8, local_size_y = 8) in;

#include "gbuffer_input.glsl"
#include "camera_input.glsl"

layout(binding = 3) uniform sampler2D u_source;
layout(r32f, binding = 0) uniform writeonly image2D u_out;

uniform int u_scale;
uniform int u_radius;        // source pixels
uniform float u_sigma;       // source pixels
uniform float u_depth_sigma; // fraction of the depth

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_out)))) return;
    vec3 p, n;
    int atom;
    if (!gbuffer_fetch(px, p, n, atom)) {
        imageStore(u_out, px, vec4(1.0));
        return;
    }
    ivec2 source_size = textureSize(u_source, 0);
    ivec2 gb_size = textureSize(u_gb_ids, 0);
    float depth = view_depth(p);
    ivec2 centre = min(px / u_scale, source_size - 1);
    float sum = 0.0, weights = 0.0;
    for (int dy = -u_radius; dy <= u_radius; ++dy) {
        for (int dx = -u_radius; dx <= u_radius; ++dx) {
            ivec2 s = centre + ivec2(dx, dy);
            if (any(lessThan(s, ivec2(0))) || any(greaterThanEqual(s, source_size))) continue;
            ivec2 g = min(s * u_scale, gb_size - 1);  // the G-buffer pixel the sample was made at
            if (!gbuffer_lit(g)) continue;
            float dz = (view_depth(texelFetch(u_gb_position, g, 0).xyz) - depth) / (u_depth_sigma * depth);
            float agree = max(dot(n, normalize(texelFetch(u_gb_normal, g, 0).xyz)), 0.0);
            float w = exp(-float(dx * dx + dy * dy) / (2.0 * u_sigma * u_sigma) - dz * dz) * agree * agree * agree * agree;
            sum += w * texelFetch(u_source, s, 0).r;
            weights += w;
        }
    }
    imageStore(u_out, px, vec4(weights > 1e-6 ? sum / weights : texelFetch(u_source, centre, 0).r));
}
