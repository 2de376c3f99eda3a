#version 430 core
// Occlusion atlas bake, step 2 of 3, one invocation per (atom, direction): the neighbours
// that can stop a ray of that direction from anywhere on the atom. Every such ray lies in
// the capsule of the atom's radius around the segment from its centre along the direction
// for the ray length, so a neighbour farther than r_i + r_j from that segment cannot meet
// one; the rest are listed (the test is conservative, never exact).
layout(local_size_x = 64) in;

#include "grid_traversal.glsl"
#include "atlas_bake_buffers.glsl"

void main() {
    int index = int(gl_GlobalInvocationID.x);
    if (index >= u_chunk_slots * u_directions) return;
    int local_slot = index / u_directions;
    vec3 d = directions[index % u_directions].xyz;
    float radius = spheres[int(slot_atoms[chunk_slot(local_slot)])].w;
    int base = index * MAX_CANDIDATES;
    int first = local_slot * MAX_NEIGHBOURS;
    int n = 0;
    for (int k = 0; k < counts[2 * local_slot]; ++k) {
        vec4 s = neighbours[first + k];
        float t = clamp(dot(s.xyz, d), 0.0, u_distance);
        vec3 off = s.xyz - t * d;
        float reach = radius + s.w;
        if (dot(off, off) >= reach * reach) continue;
        if (n < MAX_CANDIDATES) candidates[base + n++] = s;
        else atomicAdd(overflow[0], 1u);
    }
    candidate_counts[index] = n;
}
