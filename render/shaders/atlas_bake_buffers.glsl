// Storage the occlusion atlas's bake steps share (render/lighting/ao/precomputed.py), one
// chunk of u_chunk_slots patches at a time: entries u_first_slot.. of the slot list (every
// patch, or those near the probe for its light). Neighbours and candidates
// are stored as spheres relative to the atom's centre (centre - atom centre, radius), so
// the inner loops read them in order, with no index into the sphere buffer.
#define MAX_NEIGHBOURS 1024
#define MAX_OVERLAPS 32
#define MAX_CANDIDATES 95

layout(std430, binding = 4) readonly buffer SlotAtoms { uint slot_atoms[]; };   // atom of each patch
layout(std430, binding = 5) buffer Neighbours { vec4 neighbours[]; };           // chunk x MAX_NEIGHBOURS
layout(std430, binding = 6) buffer Overlaps { vec4 overlaps[]; };               // chunk x MAX_OVERLAPS
layout(std430, binding = 7) buffer Counts { int counts[]; };                    // chunk x (neighbours, overlaps)
layout(std430, binding = 8) readonly buffer Directions { vec4 directions[]; };  // the D ray directions
layout(std430, binding = 9) buffer Candidates { vec4 candidates[]; };           // chunk x D x MAX_CANDIDATES
layout(std430, binding = 10) buffer CandidateCounts { int candidate_counts[]; };  // chunk x D
layout(std430, binding = 11) buffer Overflow { uint overflow[]; };              // lists that were full
layout(std430, binding = 12) readonly buffer SlotList { uint slot_list[]; };    // the patches to bake

uniform int u_first_slot;
uniform int u_chunk_slots;
uniform int u_directions;
uniform float u_distance;    // Å, the rays' length
uniform float u_max_radius;  // Å, the largest van der Waals radius

int chunk_slot(int local_slot) { return int(slot_list[u_first_slot + local_slot]); }
