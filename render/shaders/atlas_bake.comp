#version 430 core
// Occlusion atlas bake, step 4 of 4, one work group per patch of the chunk, an invocation
// per seen texel: at the atom's surface point in the texel's direction, the ambient
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


// A seen texel's channels.
void bake_texel(int local_slot, int index) {
    ivec2 texel = ivec2(index % u_patch, index / u_patch);
    int slot = chunk_slot(local_slot);
    int atom = int(slot_atoms[slot]);
    vec4 self_sphere = grid_sphere(atom);
    vec3 n = texel_normals[index].xyz;
    vec3 x = self_sphere.xyz + self_sphere.w * n;
    ivec2 at = tile_origin(slot) + texel;
    vec4 value = imageLoad(u_atlas, at);
    vec3 o = ray_origin(x, n);
#ifdef BAKE_AMBIENT
    {   // the open rays' cosine weights over all rays' (texel_normals' w, the sum of n.d over the directions facing it)
        float open = 0.0;
        int row = (local_slot * u_patch * u_patch + index) * u_direction_words;
        for (int word = 0; word < u_direction_words; ++word) {
            uint bits = facing_directions[index * u_direction_words + word] & ~blocked_directions[row + word];
            while (bits != 0u) {
                open += dot(n, directions[word * 32 + findLSB(bits)].xyz);
                bits &= bits - 1u;
            }
        }
        float weight = texel_normals[index].w;
        value.r = weight == 0.0 ? 0.0 : min(open / weight, 1.0);
    }
#endif
#ifdef BAKE_SUN
    value.g = dot(n, u_sun_dir) > 0.0 ? trace_sun_visibility(o, u_sun_dir, atom, vec2(0.0), 0.0, false) : 0.0;
#endif
#ifdef BAKE_PROBE
    {
        vec3 to_light = u_probe_light_pos - o;
        float t_max = length(to_light);
        vec3 d = to_light / max(t_max, 1e-30);
        value.b = distance(u_probe_light_pos, x) > u_probe_light_radius ? 1.0
            : (dot(n, d) > 0.0 ? trace_visibility(o, d, 0.0, t_max, atom, vec2(0.0), 0.0, false) : 0.0);
    }
#endif
    imageStore(u_atlas, at, value);
}

// An unseen texel: -1 in the channels baked, for atlas_fill.comp.
void mark_unseen(int local_slot, int index) {
    ivec2 at = tile_origin(chunk_slot(local_slot)) + ivec2(index % u_patch, index / u_patch);
    vec4 value = imageLoad(u_atlas, at);
#ifdef BAKE_AMBIENT
    value.r = -1.0;
#endif
#ifdef BAKE_SUN
    value.g = -1.0;
#endif
#ifdef BAKE_PROBE
    value.b = -1.0;
#endif
    imageStore(u_atlas, at, value);
}

// The patch's seen texels, in order, so the invocations that trace run side by side and
// the unseen ones take no lane of a traced pass.
shared int seen_list[MAX_PATCH_TEXELS];
shared int seen_count;

void main() {
    int local_slot = int(gl_WorkGroupID.x);
    if (local_slot >= u_chunk_slots) return;
    int texels = u_patch * u_patch;
    if (gl_LocalInvocationIndex == 0u) {
        int n = 0;
        for (int word = 0; word < u_texel_words; ++word) {
            uint bits = seen_masks[local_slot * u_texel_words + word];
            while (bits != 0u) {
                seen_list[n++] = word * 32 + findLSB(bits);
                bits &= bits - 1u;
            }
        }
        seen_count = n;
    }
    barrier();
    for (int k = int(gl_LocalInvocationIndex); k < seen_count; k += 64) bake_texel(local_slot, seen_list[k]);
    for (int index = int(gl_LocalInvocationIndex); index < texels; index += 64)
        if (!texel_seen(local_slot, index)) mark_unseen(local_slot, index);
}
