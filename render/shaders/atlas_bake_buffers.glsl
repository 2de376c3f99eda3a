// Storage every step of the occlusion atlas's bake reads (render/lighting/ao/precomputed.py),
// one chunk of u_chunk_slots patches at a time: entries u_first_slot.. of the slot list
// (every patch, or those near the probe for its light). The rays' steps add
// atlas_ray_buffers.glsl; each program declares only what it reads, since llvmpipe allows
// 16 storage blocks a compute program.
#define MAX_PATCH_TEXELS 4096  // 64 x 64, the largest patch (render/lighting/settings.py PATCH_RANGE)

layout(std430, binding = 4) readonly buffer SlotAtoms { uint slot_atoms[]; };   // atom of each patch
layout(std430, binding = 12) readonly buffer SlotList { uint slot_list[]; };    // the patches to bake
// Per patch of the chunk, u_texel_words words: bit t % 32 of word t / 32 set when texel t is
// seen — its point lies neither inside another kept atom nor cut away (step 1 marks them);
// the rays of unseen texels are never traced.
layout(std430, binding = 18) buffer SeenTexels { uint seen_masks[]; };

// Each texel's direction, texel (i, j) at i + P j: the same for every patch, computed once
// (a uniform block: the invocations that read one texel at once read it in one load).
layout(std140, binding = 0) uniform TexelNormals { vec4 texel_normals[MAX_PATCH_TEXELS]; };

uniform int u_first_slot;
uniform int u_chunk_slots;
uniform int u_texel_words;  // ceil(P^2 / 32): words of a per-texel bit mask

int chunk_slot(int local_slot) { return int(slot_list[u_first_slot + local_slot]); }

bool texel_seen(int local_slot, int texel) {
    return ((seen_masks[local_slot * u_texel_words + texel / 32] >> uint(texel % 32)) & 1u) != 0u;
}
