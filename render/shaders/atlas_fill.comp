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
    bvec3 unseen = lessThan(value.rgb, vec3(0.0));
    if (any(unseen)) {  // each neighbour read once for every channel
        ivec2 origin = (at / u_patch) * u_patch;
        vec3 sum = vec3(0.0), count = vec3(0.0);
        for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            vec3 v = imageLoad(u_from, clamp(at + ivec2(dx, dy), origin, origin + u_patch - 1)).rgb;
            vec3 seen = vec3(greaterThanEqual(v, vec3(0.0)));
            sum += v * seen;
            count += seen;
        }
        vec3 filled = mix(vec3(u_last != 0 ? 0.0 : -1.0), sum / max(count, vec3(1.0)), greaterThan(count, vec3(0.0)));
        value.rgb = mix(value.rgb, filled, unseen);
    }
    imageStore(u_to, at, value);
}
