#version 430 core
// Occlusion atlas bake, after step 4: a hidden texel (marked -1, never seen: inside another
// atom, or cut away) takes the mean of the seen texels around it in its patch, so that a
// bilinear lookup next to the seam between two atoms reads the seam's own values rather
// than a dark rim
// (QuteMol smooths its patches over the bright texels only, pyQuteMol OctaMap.py Smooth).
// Run twice, from one texture into another; what is still unseen after that becomes 0.
layout(local_size_x = 8, local_size_y = 8) in;

#include "atlas_common.glsl"

layout(rgba16f, binding = 0) uniform readonly image2D u_from;
layout(rgba16f, binding = 1) uniform writeonly image2D u_to;
uniform int u_last;  // the last round: what is left unseen becomes 0

void main() {
    ivec2 at = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(at, imageSize(u_from)))) return;
    vec4 value = imageLoad(u_from, at);
    ivec2 origin = (at / u_patch) * u_patch;
    for (int c = 0; c < 3; ++c) {
        if (value[c] >= 0.0) continue;
        float sum = 0.0, count = 0.0;
        for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 q = clamp(at + ivec2(dx, dy), origin, origin + u_patch - 1);
            float v = imageLoad(u_from, q)[c];
            if (v >= 0.0) { sum += v; count += 1.0; }
        }
        value[c] = count > 0.0 ? sum / count : (u_last != 0 ? 0.0 : -1.0);
    }
    imageStore(u_to, at, value);
}
