#version 430 core
// Occlusion atlas bake, step 2 of 4, one work group per atom of the chunk, an invocation per
// four directions: the neighbours that can stop a ray of a direction from anywhere on the
// atom. Every such ray lies in the capsule of the atom's radius around the segment from its
// centre along the direction for the ray length, so a neighbour farther than r_i + r_j from
// that segment cannot meet one; the rest are marked (the test is conservative, never
// exact). Each neighbour read from memory is tested against four directions at once, and
// each invocation writes one word per 32 neighbours and direction.
layout(local_size_x = 64) in;

#include "grid_traversal.glsl"
#include "atlas_bake_buffers.glsl"
#include "atlas_ray_buffers.glsl"

vec3 direction_or_none(int dir) { return dir < u_directions ? directions[dir].xyz : vec3(0.0); }

void main() {
    int local_slot = int(gl_WorkGroupID.x);
    if (local_slot >= u_chunk_slots) return;
    float radius = spheres[int(slot_atoms[chunk_slot(local_slot)])].w;
    int first = local_slot * MAX_NEIGHBOURS;
    int count = counts[local_slot];
    for (int dir = 4 * int(gl_LocalInvocationIndex); dir < u_directions; dir += 4 * 64) {
        vec3 d0 = direction_or_none(dir), d1 = direction_or_none(dir + 1);
        vec3 d2 = direction_or_none(dir + 2), d3 = direction_or_none(dir + 3);
        vec4 dx = vec4(d0.x, d1.x, d2.x, d3.x), dy = vec4(d0.y, d1.y, d2.y, d3.y), dz = vec4(d0.z, d1.z, d2.z, d3.z);
        for (int word = 0; word * 32 < count; ++word) {
            uvec4 mask = uvec4(0u);
            for (int bit = 0; bit < 32 && word * 32 + bit < count; ++bit) {
                vec4 s = neighbours[first + word * 32 + bit];
                vec4 t = clamp(s.x * dx + s.y * dy + s.z * dz, 0.0, u_distance);
                vec4 ox = s.x - t * dx, oy = s.y - t * dy, oz = s.z - t * dz;
                float reach = radius + s.w;
                mask |= uvec4(lessThan(ox * ox + oy * oy + oz * oz, vec4(reach * reach))) << uint(bit);
            }
            for (int j = 0; j < 4 && dir + j < u_directions; ++j)
                candidate_masks[((local_slot * u_directions + dir + j) * MASK_WORDS) + word] = mask[j];
        }
    }
}
