#version 430 core
// Occlusion atlas bake, step 3 of 4, one work group per atom of the chunk, an invocation per
// direction: which of the seen texels facing that direction have their ray blocked
// (u_distance long from the texel's surface point, cut by the clip planes and the cube as
// everywhere else). The texels are taken from the bits of (facing the direction) and (seen),
// eight at a time held as two vec4 quads, so each candidate read from memory is tested
// against eight rays that all count (four quads were slower: registers ran out); texels
// facing away or hidden — inside another atom or cut away — never take a place. Rays the
// culling removes whole are left unblocked: they are open. Directions are uploaded in
// clusters of nearby ones, so the invocations that run side by side stop together.
layout(local_size_x = 64) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "atlas_bake_buffers.glsl"
#include "atlas_ray_buffers.glsl"
#include "atlas_common.glsl"

// Four texels' rays, one per component: origins relative to the atom's centre (x, y, z),
// the kept part [t0, t1] of each, whether it counts at all (a texel was taken, not culled
// whole), and whether it is still open (kept, and no candidate has blocked it). For the
// candidates' tests block_ready holds each origin as its part across the direction
// (x, y, z) and its distance along it (along).
struct Quad { vec4 x, y, z, along, t0, t1, keep, open; };

// Texel t's ray origin relative to the atom's centre, and whether there is such a texel (t >= 0).
vec4 texel_origin(int t, vec4 self_sphere) {
    vec3 n = texel_normals[max(t, 0)].xyz;
    return vec4(ray_origin(self_sphere.xyz + self_sphere.w * n, n) - self_sphere.xyz, t >= 0 ? 1.0 : 0.0);
}

// Texels t.x..t.w (written out: a loop writing components by index was much slower).
Quad quad_rays(ivec4 t, vec4 self_sphere) {
    vec4 p0 = texel_origin(t.x, self_sphere), p1 = texel_origin(t.y, self_sphere);
    vec4 p2 = texel_origin(t.z, self_sphere), p3 = texel_origin(t.w, self_sphere);
    Quad r;
    r.x = vec4(p0.x, p1.x, p2.x, p3.x);
    r.y = vec4(p0.y, p1.y, p2.y, p3.y);
    r.z = vec4(p0.z, p1.z, p2.z, p3.z);
    r.keep = vec4(p0.w, p1.w, p2.w, p3.w);
    r.along = vec4(0.0);
    r.t0 = vec4(0.0);
    r.t1 = vec4(u_distance);
    r.open = r.keep;
    return r;
}

// The origins split along and across d, once per quad, so a candidate's test needs no
// projection of its own: |f - t d|^2 = |f across d|^2 + (f.d - t)^2 for f = centre - origin.
void block_ready(inout Quad r, vec3 d) {
    r.along = r.x * d.x + r.y * d.y + r.z * d.z;
    r.x -= r.along * d.x;
    r.y -= r.along * d.y;
    r.z -= r.along * d.z;
}

// The texels still to take, as a stream over the words of (facing & seen).
#ifdef TWO_TEXEL_WORDS
// At most 64 texels a patch (P <= 8): both words at once, each texel taken without a loop
// (on llvmpipe a loop costs every call, even when it never turns).
struct Texels { uvec2 bits; };

Texels texel_stream(int dir, int local_slot) {
    int f = dir * u_texel_words, s = local_slot * u_texel_words;
    uint high = u_texel_words > 1 ? facing_masks[f + 1] & seen_masks[s + 1] : 0u;
    return Texels(uvec2(facing_masks[f] & seen_masks[s], high));
}

// The next texel of the stream, or -1 once it is empty.
int next_texel(inout Texels s) {
    bool low = s.bits.x != 0u;
    int t = low ? findLSB(s.bits.x) : (s.bits.y != 0u ? 32 + findLSB(s.bits.y) : -1);
    uvec2 taken = s.bits & (s.bits - 1u);  // each word less its lowest bit
    s.bits = low ? uvec2(taken.x, s.bits.y) : uvec2(0u, taken.y);
    return t;
}
#else
// The word being read and its bits not yet taken.
struct Texels { int word; uint bits; int facing; int seen; };

uint texel_word(Texels s) { return facing_masks[s.facing + s.word] & seen_masks[s.seen + s.word]; }

Texels texel_stream(int dir, int local_slot) {
    Texels s = Texels(0, 0u, dir * u_texel_words, local_slot * u_texel_words);
    s.bits = texel_word(s);
    return s;
}

// The next texel of the stream, or -1 once it is empty.
int next_texel(inout Texels s) {
    while (s.bits == 0u && s.word + 1 < u_texel_words) {
        ++s.word;
        s.bits = texel_word(s);
    }
    if (s.bits == 0u) return -1;
    int t = s.word * 32 + findLSB(s.bits);
    s.bits &= s.bits - 1u;
    return t;
}
#endif

ivec4 next_four(inout Texels s) {
    int a = next_texel(s), b = next_texel(s), c = next_texel(s), d = next_texel(s);
    return ivec4(a, b, c, d);
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
    r.open = r.keep;
}

// occluder_visibility's hard test of sphere s (relative to the atom's centre; `across` its
// centre's part across d, `along` its distance along d), without its square root, for the
// quad's four rays; returns how many kept rays are still open.
float block_quad(inout Quad r, vec4 s, vec3 across, float along) {
    vec4 fx = across.x - r.x, fy = across.y - r.y, fz = across.z - r.z;
    vec4 a = along - r.along;
    vec4 beyond = a - clamp(a, r.t0, r.t1);
    vec4 d2 = fx * fx + fy * fy + fz * fz + beyond * beyond;
    r.open = min(r.open, step(vec4(s.w * s.w), d2));
    return dot(r.open, vec4(1.0));
}

// Marks direction `dir` blocked for the texels of the quad whose ray a candidate stopped (each
// texel's bits are shared by the invocations of all directions, hence the atomic or).
void record(int row, int t, float blocked, int word, uint bit) {
    if (blocked > 0.0) atomicOr(blocked_directions[(row + t) * u_direction_words + word], bit);
}

void record_quad(int local_slot, ivec4 t, Quad r, int dir) {
    int row = local_slot * u_patch * u_patch, word = dir / 32;
    uint bit = 1u << uint(dir % 32);
#ifdef NO_CLIPPING  // kept: taken (so the quad holds no `keep` through the candidates' loop)
    vec4 blocked = vec4(greaterThanEqual(t, ivec4(0))) - r.open;
#else
    vec4 blocked = r.keep - r.open;
#endif
    record(row, t.x, blocked.x, word, bit);  // written out, as in quad_rays
    record(row, t.y, blocked.y, word, bit);
    record(row, t.z, blocked.z, word, bit);
    record(row, t.w, blocked.w, word, bit);
}

void main() {
    int local_slot = int(gl_WorkGroupID.x);
    if (local_slot >= u_chunk_slots) return;
    vec4 self_sphere = grid_sphere(int(slot_atoms[chunk_slot(local_slot)]));
    int count = counts[local_slot];
    bool clipping = u_clip_count > 0 || u_cube_on != 0;
    for (int dir = int(gl_LocalInvocationIndex); dir < u_directions; dir += 64) {
        vec3 d = directions[dir].xyz;
        int list = (local_slot * u_directions + dir) * MASK_WORDS;
        Texels texels = texel_stream(dir, local_slot);
        for (;;) {
            ivec4 ta = next_four(texels);
            if (ta.x < 0) break;
            ivec4 tb = next_four(texels);
            Quad a = quad_rays(ta, self_sphere);
            Quad b = quad_rays(tb, self_sphere);
#ifndef NO_CLIPPING
            if (clipping) {
                clip_quad(a, self_sphere, d);
                clip_quad(b, self_sphere, d);
            }
#endif
            block_ready(a, d);
            block_ready(b, d);
            bool open = dot(a.open + b.open, vec4(1.0)) > 0.0;
            for (int word = 0; open && word * 32 < count; ++word) {
                uint mask = candidate_masks[list + word];
                while (open && mask != 0u) {
                    int bit = findLSB(mask);
                    mask &= mask - 1u;
                    vec4 s = imageLoad(u_neighbours, ivec2(word * 32 + bit, local_slot));
                    float along = dot(s.xyz, d);
                    vec3 across = s.xyz - along * d;
                    open = block_quad(a, s, across, along) + block_quad(b, s, across, along) > 0.0;
                }
            }
            record_quad(local_slot, ta, a, dir);
            record_quad(local_slot, tb, b, dir);
        }
    }
}
