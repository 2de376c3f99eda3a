#version 430 core
// Occlusion atlas bake, step 1 of 4, one invocation per atom of the chunk: the atom's
// neighbours within reach of its rays (centre distance < r_i + ray length + r_j; with
// u_gather_neighbours 0 none, for a bake of the lights alone), and those overlapping it
// (centre distance < r_i + r_j), and with those which of its texels are seen; a hidden one is
// never seen, its rays not traced: inside another atom, or cut away by a clip plane or the
// cube (an atom crossing a face shows its cap there, not its sphere). They come from the
// kept atoms' own cells (render/lighting/ao/precomputed.py KeptCells: the spheres the
// culling keeps, each once, in the cell of its centre, stored in place), so every entry
// read is one load of a sphere that counts; cells wholly out of reach are skipped.
layout(local_size_x = 64) in;

#include "culling.glsl"
#include "atlas_bake_buffers.glsl"
#include "atlas_ray_buffers.glsl"
#include "atlas_common.glsl"

layout(std430, binding = 13) readonly buffer KeptStart { uint kept_start[]; };     // CSR offsets per cell
layout(std430, binding = 14) readonly buffer KeptSpheres { vec4 kept_spheres[]; };  // centre, vdW radius
layout(std430, binding = 15) readonly buffer SlotEntry { uint slot_entry[]; };      // each patch's own entry

uniform vec3 u_kept_origin;  // Å, corner of cell (0, 0, 0)
uniform float u_kept_cell;   // Å
uniform ivec3 u_kept_dims;
uniform int u_gather_neighbours;

void main() {
    int local_slot = int(gl_GlobalInvocationID.x);
    if (local_slot >= u_chunk_slots) return;
    uint self_entry = slot_entry[chunk_slot(local_slot)];
    vec4 self_sphere = kept_spheres[self_entry];
    float ray = u_gather_neighbours != 0 ? u_distance : 0.0;
    float reach = self_sphere.w + ray + u_max_radius;
    vec3 local = self_sphere.xyz - u_kept_origin;
    ivec3 lo = clamp(ivec3(floor((local - reach) / u_kept_cell)), ivec3(0), u_kept_dims - 1);
    ivec3 hi = clamp(ivec3(floor((local + reach) / u_kept_cell)), ivec3(0), u_kept_dims - 1);
    int n = 0, n_over = 0;
    for (int z = lo.z; z <= hi.z; ++z)
    for (int y = lo.y; y <= hi.y; ++y)
    for (int x = lo.x; x <= hi.x; ++x) {
        ivec3 cell3 = ivec3(x, y, z);
        vec3 gap = local - clamp(local, vec3(cell3) * u_kept_cell, vec3(cell3 + 1) * u_kept_cell);
        if (dot(gap, gap) >= reach * reach) continue;
        int cell = x + u_kept_dims.x * (y + u_kept_dims.y * z);
        for (uint k = kept_start[cell]; k < kept_start[cell + 1]; ++k) {
            vec4 s = kept_spheres[k];
            vec4 rel = vec4(s.xyz - self_sphere.xyz, s.w);
            float dist2 = dot(rel.xyz, rel.xyz), within = self_sphere.w + ray + s.w, touch = self_sphere.w + s.w;
            if (k == self_entry || dist2 >= within * within) continue;
            if (dist2 < touch * touch && n_over < MAX_OVERLAPS) overlaps[local_slot * MAX_OVERLAPS + n_over++] = rel;
            if (u_gather_neighbours == 0) continue;
            if (n < MAX_NEIGHBOURS) neighbours[local_slot * MAX_NEIGHBOURS + n++] = rel;
            else atomicAdd(overflow[0], 1u);
        }
    }
    counts[local_slot] = n;
    int texels = u_patch * u_patch;
    uint seen = 0u;
    for (int texel = 0; texel < texels; ++texel) {
        vec3 x_local = self_sphere.w * texel_normals[texel].xyz;  // the texel's point relative to the atom's centre
        bool hidden = point_cut(self_sphere.xyz + x_local);
        for (int k = 0; k < n_over && !hidden; ++k) {
            vec4 s = overlaps[local_slot * MAX_OVERLAPS + k];
            hidden = distance(x_local, s.xyz) < s.w;
        }
        if (!hidden) seen |= 1u << uint(texel % 32);
        for (int word = 0; !hidden && u_gather_neighbours != 0 && word < u_direction_words; ++word)
            blocked_directions[(local_slot * texels + texel) * u_direction_words + word] = 0u;  // the rays step ors into it
        if (texel % 32 == 31 || texel == texels - 1) {
            seen_masks[local_slot * u_texel_words + texel / 32] = seen;
            seen = 0u;
        }
    }
}
