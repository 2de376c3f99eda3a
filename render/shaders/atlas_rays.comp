#version 430 core
// Occlusion atlas bake, step 3 of 4, one work group per atom of the chunk, an invocation per
// direction: which of the texels facing that direction have their ray blocked (u_distance
// long from the texel's surface point, cut by the clip planes and the cube as everywhere
// else), BLOCK_TEXELS texels at a time held as two vec4 quads, so each candidate read from
// memory is tested against eight rays (four quads were slower: registers ran out), and
// only rays that count are tested (texels facing away, or hidden — inside another atom or
// cut away — never are). Rays the culling removes whole are left unblocked: they are open.
// Directions are uploaded in clusters of nearby ones, so the invocations that run side by
// side stop together.
layout(local_size_x = 64) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "atlas_bake_buffers.glsl"
#include "atlas_ray_buffers.glsl"
#include "atlas_common.glsl"

// Four texels' rays, one per component: origins relative to the atom's centre, the kept
// part [t0, t1] of each, whether it counts at all (a texel of the patch facing the
// direction, not culled whole), and whether a candidate has blocked it.
struct Quad { vec4 x, y, z, t0, t1, keep, blocked; };

// Entry k of a facing list of `count` texels (`list`: where it starts): the texel's ray
// origin relative to the atom's centre, and whether its ray is traced (there is such an
// entry, and the texel is not hidden; `hidden`: the patch's flags).
vec4 facing_origin(int list, int count, int k, vec4 self_sphere, int hidden) {
    bool inside = k < count;
    int texel = inside ? facing[list + k] : 0;
    vec3 n = texel_normals[texel].xyz;
    bool traced = inside && hidden_texels[hidden + texel] == 0;
    return vec4(ray_origin(self_sphere.xyz + self_sphere.w * n, n) - self_sphere.xyz, traced ? 1.0 : 0.0);
}

// Entries first..first+3 (written out: a loop writing components by index was much slower).
Quad quad_rays(int list, int count, int first, vec4 self_sphere, int hidden) {
    vec4 p0 = facing_origin(list, count, first, self_sphere, hidden);
    vec4 p1 = facing_origin(list, count, first + 1, self_sphere, hidden);
    vec4 p2 = facing_origin(list, count, first + 2, self_sphere, hidden);
    vec4 p3 = facing_origin(list, count, first + 3, self_sphere, hidden);
    Quad r;
    r.x = vec4(p0.x, p1.x, p2.x, p3.x);
    r.y = vec4(p0.y, p1.y, p2.y, p3.y);
    r.z = vec4(p0.z, p1.z, p2.z, p3.z);
    r.keep = vec4(p0.w, p1.w, p2.w, p3.w);
    r.t0 = vec4(0.0);
    r.t1 = vec4(u_distance);
    r.blocked = vec4(0.0);
    return r;
}

// The clip planes and the cube cut the quad's rays (clip_ray; a ray they remove whole no
// longer counts). Kept apart from quad_rays: clip_ray inlined per texel there made every
// bake slower, clipped or not.
void clip_quad(inout Quad r, vec4 self_sphere, vec3 d) {
    for (int j = 0; j < 4; ++j) {
        float a = 0.0, b = u_distance;
        vec3 cut_normal;
        bool kept = clip_ray(self_sphere.xyz + vec3(r.x[j], r.y[j], r.z[j]), d, a, b, cut_normal);
        r.t0[j] = a;
        r.t1[j] = max(a, b);
        r.keep[j] = kept ? r.keep[j] : 0.0;
    }
}

// occluder_visibility's hard test of sphere s (relative to the atom's centre), without
// its square root, for the quad's four rays; returns how many kept rays are still open.
float block_quad(inout Quad r, vec4 s, vec3 d) {
    vec4 fx = s.x - r.x, fy = s.y - r.y, fz = s.z - r.z;
    vec4 t = clamp(fx * d.x + fy * d.y + fz * d.z, r.t0, r.t1);
    vec4 qx = fx - t * d.x, qy = fy - t * d.y, qz = fz - t * d.z;
    r.blocked = max(r.blocked, vec4(lessThan(qx * qx + qy * qy + qz * qz, vec4(s.w * s.w))) * r.keep);
    return dot(r.keep - r.blocked, vec4(1.0));
}

uint quad_bits(Quad r, int shift) {
    uvec4 b = uvec4(greaterThan(r.blocked, vec4(0.0))) << (uvec4(0u, 1u, 2u, 3u) + uint(shift));
    return b.x | b.y | b.z | b.w;
}

void main() {
    int local_slot = int(gl_WorkGroupID.x);
    if (local_slot >= u_chunk_slots) return;
    vec4 self_sphere = spheres[int(slot_atoms[chunk_slot(local_slot)])];
    int first = local_slot * MAX_NEIGHBOURS;
    int count = counts[local_slot];
    int hidden = local_slot * u_patch * u_patch;
    bool clipping = u_clip_count > 0 || u_cube_on != 0;
    for (int dir = int(gl_LocalInvocationIndex); dir < u_directions; dir += 64) {
        vec3 d = directions[dir].xyz;
        int list = (local_slot * u_directions + dir) * MASK_WORDS;
        int texels = dir * (u_patch * u_patch + 1);
        int n_facing = facing[texels];
        for (int block = 0; block * BLOCK_TEXELS < n_facing; ++block) {
            int base = block * BLOCK_TEXELS;
            Quad a = quad_rays(texels + 1, n_facing, base, self_sphere, hidden);
            Quad b = quad_rays(texels + 1, n_facing, base + 4, self_sphere, hidden);
#ifndef NO_CLIPPING
            if (clipping) {
                clip_quad(a, self_sphere, d);
                clip_quad(b, self_sphere, d);
            }
#endif
            bool open = dot(a.keep + b.keep, vec4(1.0)) > 0.0;
            for (int word = 0; open && word * 32 < count; ++word) {
                uint mask = candidate_masks[list + word];
                while (open && mask != 0u) {
                    int bit = findLSB(mask);
                    mask &= mask - 1u;
                    vec4 s = neighbours[first + word * 32 + bit];
                    open = block_quad(a, s, d) + block_quad(b, s, d) > 0.0;
                }
            }
            blocked_masks[(local_slot * u_directions + dir) * u_blocks + block] =
                quad_bits(a, 0) | quad_bits(b, 4);
        }
    }
}
