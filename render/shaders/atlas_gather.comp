#version 430 core
// Occlusion atlas bake, step 1 of 3, one invocation per atom of the chunk: the atom's
// neighbours within reach of its rays (centre distance < r_i + ray length + r_j), and those
// overlapping it (centre distance < r_i + r_j, for the hidden-texel test), gathered from the
// grid's cells around it (cells wholly out of reach are skipped). A sphere is stored in
// every cell its expanded sphere overlaps; it is taken only from the cell that holds its
// centre, so each is listed once. Only cells next to the walk range (the cube's cells, with
// a cube) can hold the centre of an atom the culling keeps.
layout(local_size_x = 64) in;

#include "grid_traversal.glsl"
#include "atlas_bake_buffers.glsl"

void main() {
    int local_slot = int(gl_GlobalInvocationID.x);
    if (local_slot >= u_chunk_slots) return;
    int atom = int(slot_atoms[chunk_slot(local_slot)]);
    vec4 self_sphere = spheres[atom];
    float reach = self_sphere.w + u_distance + u_max_radius;
    vec3 local = self_sphere.xyz - u_grid_origin;
    ivec3 first = max(u_walk_lo - 1, ivec3(0)), last = min(u_walk_hi + 1, u_grid_dims - 1);
    ivec3 lo = clamp(ivec3(floor((local - reach) / u_cell_size)), first, last);
    ivec3 hi = clamp(ivec3(floor((local + reach) / u_cell_size)), first, last);
    int n = 0, n_over = 0;
    for (int z = lo.z; z <= hi.z; ++z)
    for (int y = lo.y; y <= hi.y; ++y)
    for (int x = lo.x; x <= hi.x; ++x) {
        ivec3 cell3 = ivec3(x, y, z);
        vec3 gap = local - clamp(local, vec3(cell3) * u_cell_size, vec3(cell3 + 1) * u_cell_size);
        if (dot(gap, gap) >= reach * reach) continue;
        int cell = x + u_grid_dims.x * (y + u_grid_dims.y * z);
        for (uint k = cell_start[cell]; k < cell_start[cell + 1]; ++k) {
            int other = int(cell_atoms[k]);
            if (other == atom || (culled[other] & CULLED) != 0u) continue;
            vec4 s = spheres[other];
            if (clamp(ivec3(floor((s.xyz - u_grid_origin) / u_cell_size)), ivec3(0), u_grid_dims - 1) != cell3)
                continue;
            vec4 rel = vec4(s.xyz - self_sphere.xyz, s.w);
            float dist = length(rel.xyz);
            if (dist < self_sphere.w + s.w && n_over < MAX_OVERLAPS) overlaps[local_slot * MAX_OVERLAPS + n_over++] = rel;
            if (dist >= self_sphere.w + u_distance + s.w) continue;
            if (n < MAX_NEIGHBOURS) neighbours[local_slot * MAX_NEIGHBOURS + n++] = rel;
            else atomicAdd(overflow[0], 1u);
        }
    }
    counts[2 * local_slot] = n;
    counts[2 * local_slot + 1] = n_over;
}
