// Storage the occlusion atlas's bake steps share (render/lighting/ao/precomputed.py), one
// chunk of u_chunk_slots patches at a time: entries u_first_slot.. of the slot list (every
// patch, or those near the probe for its light). Neighbours are stored as spheres relative
// to the atom's centre (centre - atom centre, radius), so the inner loops read them in
// order, with no index into the sphere buffer. The candidates of a direction are a bit per
// neighbour (bit k % 32 of word k / 32), the rays it blocked a bit per texel that faces it
// (in the order of its facing list, BLOCK_TEXELS texels a word), so no step writes a list entry by
// entry.
#define MAX_NEIGHBOURS 1024
#define MAX_OVERLAPS 32
#define MASK_WORDS 32      // MAX_NEIGHBOURS / 32
#define BLOCK_TEXELS 8    // texels per word of the blocked masks
#define MAX_PATCH_TEXELS 4096  // 64 x 64, the largest patch (render/lighting/settings.py PATCH_RANGE)

layout(std430, binding = 4) readonly buffer SlotAtoms { uint slot_atoms[]; };   // atom of each patch
layout(std430, binding = 5) buffer Neighbours { vec4 neighbours[]; };           // chunk x MAX_NEIGHBOURS
layout(std430, binding = 6) buffer Overlaps { vec4 overlaps[]; };               // chunk x MAX_OVERLAPS
layout(std430, binding = 7) buffer Counts { int counts[]; };                    // chunk: neighbours listed
layout(std430, binding = 8) readonly buffer Directions { vec4 directions[]; };  // the D ray directions
layout(std430, binding = 9) buffer CandidateMasks { uint candidate_masks[]; };  // chunk x D x MASK_WORDS
layout(std430, binding = 10) buffer BlockedMasks { uint blocked_masks[]; };     // chunk x D x u_blocks
layout(std430, binding = 11) buffer Overflow { uint overflow[]; };              // lists that were full
layout(std430, binding = 12) readonly buffer SlotList { uint slot_list[]; };    // the patches to bake
// Per direction, the texels facing it (n.d > 0; the same for every patch): at d (P^2 + 1)
// their count, then their indices; and each texel's place in that list (-1: facing away)
// at d P^2 + texel.
layout(std430, binding = 16) readonly buffer FacingTexels { int facing[]; };
layout(std430, binding = 17) readonly buffer FacingRank { int facing_rank[]; };
// Per patch texel of the chunk (slot x P^2 + texel), 1 where its point lies inside another
// kept atom or is cut away: never seen, its rays not traced (step 1 marks them).
layout(std430, binding = 18) buffer HiddenTexels { int hidden_texels[]; };

// Each texel's direction, texel (i, j) at i + P j: the same for every patch, computed once
// (a uniform block: the invocations that read one texel at once read it in one load).
layout(std140, binding = 0) uniform TexelNormals { vec4 texel_normals[MAX_PATCH_TEXELS]; };

uniform int u_first_slot;
uniform int u_chunk_slots;
uniform int u_directions;
uniform int u_blocks;        // words of a direction's blocked mask: ceil(most texels facing a direction / BLOCK_TEXELS)
uniform float u_distance;    // Å, the rays' length
uniform float u_max_radius;  // Å, the largest van der Waals radius

int chunk_slot(int local_slot) { return int(slot_list[u_first_slot + local_slot]); }
