#version 430 core
// Occlusion atlas bake, step 2 of 4, one work group per atom of the chunk, an invocation per
// eight directions: the neighbours that can stop a ray of a direction from anywhere on the
// atom. A point o + t d of such a ray (|o| = r_i, o.d >= 0, 0 <= t <= L) lies within r_i of
// the half-line from the atom's centre along d, so a neighbour that can stop it lies within
// R = r_i + r_j of that half-line: true for exactly the directions with s.d > sqrt(|s|^2 - R^2)
// (a cone about the neighbour's centre s; every direction when |s| < R). Nor can one stop it
// whose centre lies more than its radius behind the atom's centre along d (every point of
// the ray lies ahead of the centre: it starts on the half of the atom facing d). The rest
// are marked: a few more than the capsule about the ray length's segment would keep (past
// its end, within the gather's reach), for one comparison per direction after one square
// root per neighbour; the rays step tests each exactly. Each neighbour read from memory is
// tested against eight directions at once, and each invocation writes one word per 32
// neighbours and direction.
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

// Which of the four directions' cones hold sphere s (relative to the atom's centre): its
// centre's distance along the direction is above `least`.
uvec4 meets(Four d, vec4 s, float least) {
    return uvec4(greaterThan(s.x * d.x + s.y * d.y + s.z * d.z, vec4(least)));
}

void write_masks(int local_slot, int dir, int word, uvec4 mask) {
    for (int j = 0; j < 4 && dir + j < u_directions; ++j)
        candidate_masks[((local_slot * u_directions + dir + j) * MASK_WORDS) + word] = mask[j];
}

void main() {
    int local_slot = int(gl_WorkGroupID.x);
    if (local_slot >= u_chunk_slots) return;
    float radius = grid_sphere(int(slot_atoms[chunk_slot(local_slot)])).w;
    int count = counts[local_slot];
    for (int dir = 8 * int(gl_LocalInvocationIndex); dir < u_directions; dir += 8 * 64) {
        Four a = four_directions(dir), b = four_directions(dir + 4);
        for (int word = 0; word * 32 < count; ++word) {
            uvec4 mask_a = uvec4(0u), mask_b = uvec4(0u);
            for (int bit = 0; bit < 32 && word * 32 + bit < count; ++bit) {
                vec4 s = imageLoad(u_neighbours, ivec2(word * 32 + bit, local_slot));
                float s2 = dot(s.xyz, s.xyz), reach = radius + s.w + 1e-3;  // a hair wider: float rounding
                float least = s2 > reach * reach ? sqrt(s2 - reach * reach) - 1e-3 : -s.w;
                mask_a |= meets(a, s, least) << uint(bit);
                mask_b |= meets(b, s, least) << uint(bit);
            }
            write_masks(local_slot, dir, word, mask_a);
            write_masks(local_slot, dir + 4, word, mask_b);
        }
    }
}
