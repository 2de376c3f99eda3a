// Storage the occlusion atlas's ray steps share (gather, candidates, rays; with
// atlas_bake_buffers.glsl). Neighbours are stored as spheres relative to the atom's centre
// (centre - atom centre, radius), so the inner loops read them in order, with no index into
// the sphere buffer; in an image (row = the patch's place in the chunk, column = the
// neighbour), which llvmpipe reads far faster than a storage buffer (table_image.glsl).
// The candidates of a direction are a bit per neighbour (bit k % 32 of word k / 32), so no
// step writes a list entry by entry.
#include "atlas_sum_buffers.glsl"
#define MAX_NEIGHBOURS 1024
#define MAX_OVERLAPS 32
#define MASK_WORDS 32      // MAX_NEIGHBOURS / 32
#ifndef NEIGHBOURS_ACCESS
#define NEIGHBOURS_ACCESS readonly  // the gather writes them, the later steps read them
#endif

layout(rgba32f, binding = 1) uniform NEIGHBOURS_ACCESS image2D u_neighbours;  // MAX_NEIGHBOURS x chunk

layout(std430, binding = 7) buffer Counts { int counts[]; };                    // chunk: neighbours listed
layout(std430, binding = 9) buffer CandidateMasks { uint candidate_masks[]; };  // chunk x D x MASK_WORDS
layout(std430, binding = 11) buffer Overflow { uint overflow[]; };              // lists that were full
// Per direction, the texels facing it (n.d > 0; the same for every patch): u_texel_words
// words a direction, bit t % 32 of word t / 32 for texel t.
layout(std430, binding = 16) readonly buffer FacingMasks { uint facing_masks[]; };

uniform float u_distance;    // Å, the rays' length
uniform float u_max_radius;  // Å, the largest van der Waals radius
