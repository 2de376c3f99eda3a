// What the accessibility's sums read (the rays' steps too): the D directions and, per
// direction, the rays its texels found blocked, a bit per texel that faces it (in the order
// of its facing list, BLOCK_TEXELS texels a word), and each texel's place in that list.
#define BLOCK_TEXELS 8    // texels per word of the blocked masks

layout(std430, binding = 8) readonly buffer Directions { vec4 directions[]; };  // the D ray directions
layout(std430, binding = 10) buffer BlockedMasks { uint blocked_masks[]; };     // chunk x D x u_blocks
// Each texel's place in a direction's facing list (-1: facing away), at d P^2 + texel.
layout(std430, binding = 17) readonly buffer FacingRank { int facing_rank[]; };

uniform int u_directions;
uniform int u_blocks;  // words of a direction's blocked mask: ceil(most texels facing a direction / BLOCK_TEXELS)
