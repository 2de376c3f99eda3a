#version 430 core
// Occlusion atlas bake, step 4 of 4, one work group per patch of the chunk, an invocation
// per texel: at the atom's surface point in the texel's direction, the ambient
// accessibility over the D fixed directions (cosine-weighted: sum of n.d over the rays
// step 3 found open, over the sum of n.d over all rays above the surface), the directional
// light's visibility and the probe light's (one ray each, as shadows.comp traces them: the
// sun's through its light buffer, the probe light's through the grid; beyond the probe
// light's range 1). Clip planes and the cube cut the rays as everywhere else.
// A hidden point (inside another drawn atom, or cut away) is never seen; it is marked -1
// and filled from the seen texels around it (atlas_fill.comp). Channels the bake leaves
// alone keep their value; the program is compiled per case (BAKE_AMBIENT, BAKE_SUN,
// BAKE_PROBE: the channels baked).
layout(local_size_x = 64) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "atlas_bake_buffers.glsl"
#ifdef BAKE_AMBIENT
#include "atlas_sum_buffers.glsl"
#endif
#ifdef BAKE_SUN
#include "sun_buffer.glsl"
#endif
#include "atlas_common.glsl"
#include "lights.glsl"

layout(rgba16f, binding = 0) uniform image2D u_atlas;


void bake_texel(int local_slot, int index) {
    ivec2 texel = ivec2(index % u_patch, index / u_patch);
    int slot = chunk_slot(local_slot);
    int atom = int(slot_atoms[slot]);
    vec4 self_sphere = spheres[atom];
    vec3 n = texel_normals[index].xyz;
    vec3 x = self_sphere.xyz + self_sphere.w * n;
    bool hidden = hidden_texels[local_slot * u_patch * u_patch + index] != 0;
    ivec2 at = tile_origin(slot) + texel;
    vec4 value = imageLoad(u_atlas, at);
    vec3 o = ray_origin(x, n);
#ifdef BAKE_AMBIENT
    {
        int texels = u_patch * u_patch;
        float weight = 0.0, open = 0.0;
        for (int i = 0; i < u_directions && !hidden; ++i) {
            int rank = facing_rank[i * texels + index];
            if (rank < 0) continue;
            float w = dot(n, directions[i].xyz);
            weight += w;
            uint word = blocked_masks[(local_slot * u_directions + i) * u_blocks + rank / BLOCK_TEXELS];
            if ((word & (1u << uint(rank % BLOCK_TEXELS))) == 0u) open += w;
        }
        value.r = hidden ? -1.0 : (weight == 0.0 ? 0.0 : open / weight);
    }
#endif
#ifdef BAKE_SUN
    value.g = hidden ? -1.0 : (dot(n, u_sun_dir) > 0.0
        ? trace_sun_visibility(o, u_sun_dir, atom, vec2(0.0), 0.0, false) : 0.0);
#endif
#ifdef BAKE_PROBE
    {
        vec3 to_light = u_probe_light_pos - o;
        float t_max = length(to_light);
        vec3 d = to_light / max(t_max, 1e-30);
        value.b = hidden ? -1.0 : (distance(u_probe_light_pos, x) > u_probe_light_radius ? 1.0
            : (dot(n, d) > 0.0 ? trace_visibility(o, d, 0.0, t_max, atom, vec2(0.0), 0.0, false) : 0.0));
    }
#endif
    imageStore(u_atlas, at, value);
}

void main() {
    int local_slot = int(gl_WorkGroupID.x);
    if (local_slot >= u_chunk_slots) return;
    for (int index = int(gl_LocalInvocationIndex); index < u_patch * u_patch; index += 64) bake_texel(local_slot, index);
}
