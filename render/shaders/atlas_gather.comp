#version 430 core
// Occlusion atlas bake, step 1 of 4, one invocation per atom of the chunk: the atom's
// neighbours within reach of its rays (centre distance < r_i + ray length + r_j; with
// u_gather_neighbours 0 none, for a bake of the lights alone), and those overlapping it
// (centre distance < r_i + r_j), and with those which of its texels are seen; a hidden one is
// never seen, its rays not traced: inside another atom, or cut away by a clip plane or the
// cube (an atom crossing a face shows its cap there, not its sphere). They come from the
// kept atoms' own cells (render/lighting/ao/precomputed.py KeptCells: the spheres the
// culling keeps, each once, in the cell of its centre, stored in place), so every entry
// read is one load of a sphere that counts; of each row of cells only the run the reach's
// sphere crosses is read.
layout(local_size_x = 64) in;

#define NEIGHBOURS_ACCESS writeonly
#include "culling.glsl"
#include "atlas_bake_buffers.glsl"
#include "atlas_ray_buffers.glsl"
#include "atlas_common.glsl"
#include "table_image.glsl"

layout(std430, binding = 13) readonly buffer KeptStart { uint kept_start[]; };  // CSR offsets per cell
layout(std430, binding = 15) readonly buffer SlotEntry { uint slot_entry[]; };   // each patch's own entry
// Images, not storage buffers, for the vec4s read many times (table_image.glsl): the kept
// spheres (centre, vdW radius), and each patch's overlapping neighbours (row = its place
// in the chunk), which only this step reads.
layout(rgba32f, binding = 3) readonly uniform image2D u_kept_spheres;
layout(rgba32f, binding = 2) uniform image2D u_overlaps;  // MAX_OVERLAPS x chunk

vec4 kept_sphere(uint k) { return imageLoad(u_kept_spheres, table_texel(k)); }

uniform vec3 u_kept_origin;  // Å, corner of cell (0, 0, 0)
uniform float u_kept_cell;   // Å
uniform ivec3 u_kept_dims;
uniform int u_gather_neighbours;

void main() {
    int local_slot = int(gl_GlobalInvocationID.x);
    if (local_slot >= u_chunk_slots) return;
    uint self_entry = slot_entry[chunk_slot(local_slot)];
    vec4 self_sphere = kept_sphere(self_entry);
    float ray = u_gather_neighbours != 0 ? u_distance : 0.0;
    float reach = self_sphere.w + ray + u_max_radius;
    vec3 local = self_sphere.xyz - u_kept_origin;
    ivec3 lo = clamp(ivec3(floor((local - reach) / u_kept_cell)), ivec3(0), u_kept_dims - 1);
    ivec3 hi = clamp(ivec3(floor((local + reach) / u_kept_cell)), ivec3(0), u_kept_dims - 1);
    int n = 0, n_over = 0;
    // Row by row of cells along x: a row's cells are stored one after another, so the cells
    // of a row the reach's sphere crosses are one run of entries.
    for (int z = lo.z; z <= hi.z; ++z)
    for (int y = lo.y; y <= hi.y; ++y) {
        vec2 yz = vec2(y, z) * u_kept_cell;
        vec2 gap = local.yz - clamp(local.yz, yz, yz + u_kept_cell);
        float chord2 = reach * reach - dot(gap, gap);
        if (chord2 <= 0.0) continue;
        float chord = sqrt(chord2);
        int x0 = clamp(int(floor((local.x - chord) / u_kept_cell)), lo.x, hi.x);
        int x1 = clamp(int(floor((local.x + chord) / u_kept_cell)), lo.x, hi.x);
        int row = u_kept_dims.x * (y + u_kept_dims.y * z);
        for (uint k = kept_start[row + x0]; k < kept_start[row + x1 + 1]; ++k) {
            vec4 s = kept_sphere(k);
            vec4 rel = vec4(s.xyz - self_sphere.xyz, s.w);
            float dist2 = dot(rel.xyz, rel.xyz), within = self_sphere.w + ray + s.w, touch = self_sphere.w + s.w;
            if (k == self_entry || dist2 >= within * within) continue;
            if (dist2 < touch * touch && n_over < MAX_OVERLAPS) imageStore(u_overlaps, ivec2(n_over++, local_slot), rel);
            if (u_gather_neighbours == 0) continue;
            if (n < MAX_NEIGHBOURS) imageStore(u_neighbours, ivec2(n, local_slot), rel);
            ++n;
        }
    }
    if (n > MAX_NEIGHBOURS) atomicAdd(overflow[0], 1u);  // a list that was full
    n = min(n, MAX_NEIGHBOURS);
    counts[local_slot] = n;
    int texels = u_patch * u_patch;
    uint seen = 0u;
    for (int texel = 0; texel < texels; ++texel) {
        vec3 x_local = self_sphere.w * texel_normals[texel].xyz;  // the texel's point relative to the atom's centre
        bool hidden = point_cut(self_sphere.xyz + x_local);
        for (int k = 0; k < n_over && !hidden; ++k) {
            vec4 s = imageLoad(u_overlaps, ivec2(k, local_slot));
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
