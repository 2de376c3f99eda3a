#version 430 core
// Occlusion atlas bake, step 3 of 3, one invocation per patch texel of the chunk: at the
// atom's surface point in the texel's direction, the ambient accessibility over the D fixed
// directions (cosine-weighted: sum of n.d over the unblocked rays of length u_distance, over
// the sum of n.d over all rays above the surface; the candidates of step 2 are the only
// spheres a ray can meet), the directional light's visibility and the probe light's (one
// ray through the grid each, as shadows.comp traces them; beyond the probe light's range 1).
// Clip planes and the cube cut the rays as everywhere else.
// A point inside another drawn atom is never seen; it is marked -1 and filled from the
// seen texels around it (atlas_fill.comp). Channels the bake leaves alone keep their value.
layout(local_size_x = 64) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "atlas_bake_buffers.glsl"
#include "atlas_common.glsl"
#include "lights.glsl"

layout(rgba16f, binding = 0) uniform image2D u_atlas;

uniform int u_bake_ambient;
uniform int u_bake_sun;
uniform int u_bake_probe;

void main() {
    int index = int(gl_GlobalInvocationID.x);
    int texels = u_patch * u_patch;
    if (index >= u_chunk_slots * texels) return;
    int local_slot = index / texels;
    ivec2 texel = ivec2((index % texels) % u_patch, (index % texels) / u_patch);
    int slot = chunk_slot(local_slot);
    int atom = int(slot_atoms[slot]);
    vec4 self_sphere = spheres[atom];
    vec3 n = texel_direction(texel);
    vec3 x = self_sphere.xyz + self_sphere.w * n;
    vec3 x_local = self_sphere.w * n;  // the texel's point relative to the atom's centre
    bool hidden = false;
    for (int k = 0; k < counts[2 * local_slot + 1]; ++k) {
        vec4 s = overlaps[local_slot * MAX_OVERLAPS + k];
        hidden = hidden || distance(x_local, s.xyz) < s.w;
    }
    ivec2 at = tile_origin(slot) + texel;
    vec4 value = imageLoad(u_atlas, at);
    vec3 o = ray_origin(x, n);
    vec3 o_local = o - self_sphere.xyz;
    if (u_bake_ambient != 0) {
        float weight = 0.0, open = 0.0;
        for (int i = 0; i < u_directions && !hidden; ++i) {
            vec3 d = directions[i].xyz;
            float w = dot(n, d);
            if (w <= 0.0) continue;
            weight += w;
            float t0 = 0.0, t1 = u_distance;
            vec3 cut_normal;
            bool blocked = false;
            if (clip_ray(o, d, t0, t1, cut_normal)) {
                int list = (local_slot * u_directions) + i;
                int base = list * MAX_CANDIDATES;
                for (int k = 0; k < candidate_counts[list] && !blocked; ++k) {
                    vec4 s = candidates[base + k];  // occluder_visibility's hard test, without its square root
                    vec3 f = s.xyz - o_local;
                    vec3 q = f - clamp(dot(f, d), t0, t1) * d;
                    blocked = dot(q, q) < s.w * s.w;
                }
            }
            if (!blocked) open += w;
        }
        value.r = hidden ? -1.0 : (weight == 0.0 ? 0.0 : open / weight);
    }
    if (u_bake_sun != 0) {
        value.g = hidden ? -1.0 : (dot(n, u_sun_dir) > 0.0
            ? trace_visibility(o, u_sun_dir, 0.0, BIG, atom, vec2(0.0), 0.0, false) : 0.0);
    }
    if (u_bake_probe != 0) {
        vec3 to_light = u_probe_light_pos - o;
        float t_max = length(to_light);
        vec3 d = to_light / max(t_max, 1e-30);
        value.b = hidden ? -1.0 : (distance(u_probe_light_pos, x) > u_probe_light_radius ? 1.0
            : (dot(n, d) > 0.0 ? trace_visibility(o, d, 0.0, t_max, atom, vec2(0.0), 0.0, false) : 0.0));
    }
    imageStore(u_atlas, at, value);
}
