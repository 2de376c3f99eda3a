#version 430 core
// Occlusion atlas bake, step 2 of 4, one work group per atom of the chunk, an invocation per
// eight directions: the neighbours that can stop a ray of a direction from anywhere on the
// atom. Every such ray lies in the capsule of the atom's radius around the segment from its
// centre along the direction for the ray length, so a neighbour farther than r_i + r_j from
// that segment cannot meet one; nor can one whose centre lies more than its radius behind
// the atom's centre along the direction (a ray starts on the half of the atom facing it, so
// every point of it lies ahead of the centre). The rest are marked (the test is
// conservative, never exact). Each neighbour read from memory is tested against eight directions at once, and
// each invocation writes one word per 32 neighbours and direction.
layout(local_size_x = 64) in;

#include "grid_traversal.glsl"
#include "atlas_bake_buffers.glsl"
#include "atlas_ray_buffers.glsl"

vec3 direction_or_none(int dir) { return dir < u_directions ? directions[dir].xyz : vec3(0.0); }

// Four directions as the components of three vectors.
struct Four { vec4 x, y, z; };

Four four_directions(int dir) {
    vec3 d0 = direction_or_none(dir), d1 = direction_or_none(dir + 1);
    vec3 d2 = direction_or_none(dir + 2), d3 = direction_or_none(dir + 3);
    return Four(vec4(d0.x, d1.x, d2.x, d3.x), vec4(d0.y, d1.y, d2.y, d3.y), vec4(d0.z, d1.z, d2.z, d3.z));
}

// Which of the four directions' capsules sphere s (relative to the atom's centre; `s2` its
// centre's squared distance) meets: the squared distance to the segment is |s|^2 - 2 t a + t^2
// for the clamped projection t of the projection a.
uvec4 meets(Four d, vec4 s, float s2, float reach2) {
    vec4 along = s.x * d.x + s.y * d.y + s.z * d.z;
    vec4 t = clamp(along, 0.0, u_distance);
    return uvec4(lessThan(s2 + t * (t - 2.0 * along), vec4(reach2))) & uvec4(greaterThan(along, vec4(-s.w)));
}

void write_masks(int local_slot, int dir, int word, uvec4 mask) {
    for (int j = 0; j < 4 && dir + j < u_directions; ++j)
        candidate_masks[((local_slot * u_directions + dir + j) * MASK_WORDS) + word] = mask[j];
}

void main() {
    int local_slot = int(gl_WorkGroupID.x);
    if (local_slot >= u_chunk_slots) return;
    float radius = spheres[int(slot_atoms[chunk_slot(local_slot)])].w;
    int first = local_slot * MAX_NEIGHBOURS;
    int count = counts[local_slot];
    for (int dir = 8 * int(gl_LocalInvocationIndex); dir < u_directions; dir += 8 * 64) {
        Four a = four_directions(dir), b = four_directions(dir + 4);
        for (int word = 0; word * 32 < count; ++word) {
            uvec4 mask_a = uvec4(0u), mask_b = uvec4(0u);
            for (int bit = 0; bit < 32 && word * 32 + bit < count; ++bit) {
                vec4 s = neighbours[first + word * 32 + bit];
                float s2 = dot(s.xyz, s.xyz), reach = radius + s.w + 1e-3;  // a hair wider: float rounding
                mask_a |= meets(a, s, s2, reach * reach) << uint(bit);
                mask_b |= meets(b, s, s2, reach * reach) << uint(bit);
            }
            write_masks(local_slot, dir, word, mask_a);
            write_masks(local_slot, dir + 4, word, mask_b);
        }
    }
}
