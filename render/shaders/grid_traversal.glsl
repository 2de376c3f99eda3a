// The uniform grid of molecule/grid.py on the GPU: 3D-DDA (Amanatides & Woo 1987) and the
// sphere queries shadows, ambient occlusion and path tracing share.
//
// Buffers (std430) and tables in images (table_image.glsl: llvmpipe reads an image far
// faster than a storage buffer), uploaded by render/lighting/uploaded_grid.py, layout as in
// molecule/grid.py:
//   cell_start    uint[n_cells + 1]  CSR offsets, flat cell id = ix + nx * (iy + ny * iz)
//   cell_atoms    uint[]             sphere indices per cell
//   grid_sphere   vec4 per atom      centre (Å, world frame), van der Waals radius
//   culled_flags  uint per atom      CULLED (nothing kept by the clip planes and the
//                                    navigation cube), CENTRE_CLIPPED (centre cut away)
// The grid is built with the *expanded* radii (vdW + probe), so every vdW sphere, and every
// soft-shadow shell up to the probe radius thick, lies in the cells it is stored in.
//
// Clipping: what is drawn is the spheres intersected with the kept half-spaces of the clip
// planes (a.x + d >= 0) and the navigation cube. That set is convex per sphere and the kept
// part of a ray is one interval, so rays are clipped once (clip_ray) and sphere hits only
// count inside that interval: cut-open atoms shadow with what is left of them.

layout(std430, binding = 0) readonly buffer GridCellStart { uint cell_start[]; };
layout(std430, binding = 1) readonly buffer GridCellAtoms { uint cell_atoms[]; };
#include "table_image.glsl"
layout(rgba32f, binding = 4) readonly uniform image2D u_grid_spheres;
layout(r32ui, binding = 5) readonly uniform uimage2D u_grid_culled;

vec4 grid_sphere(int atom) { return imageLoad(u_grid_spheres, table_texel(uint(atom))); }
uint culled_flags(int atom) { return imageLoad(u_grid_culled, table_texel(uint(atom))).x; }

uniform vec3 u_grid_origin;   // Å, corner of cell (0, 0, 0)
uniform float u_cell_size;    // Å
uniform ivec3 u_grid_dims;
uniform ivec3 u_walk_lo;      // inclusive cell range walks stay in: the whole grid, or the
uniform ivec3 u_walk_hi;      // navigation cube's cells (nothing outside it is drawn)

#include "constants.glsl"
#include "occluders.glsl"
#include "culling.glsl"
uniform vec4 u_probe_sphere;  // the probe as an occluder: centre, radius (w <= 0: none)
uniform float u_probe_reach;  // Å: its share of the ambient occlusion ends there (probe_occlusion)

const float BIG = 1e30;
const uint CULLED = 1u;
const uint CENTRE_CLIPPED = 2u;

// Slab test of o + t d against the box [lo, hi]; narrows [t0, t1]. An axis the ray runs
// parallel to keeps the ray only when o lies in the half-open slab [lo, hi), as on the CPU.
bool ray_box(vec3 o, vec3 d, vec3 lo, vec3 hi, inout float t0, inout float t1) {
    for (int a = 0; a < 3; ++a) {
        if (d[a] == 0.0) {
            if (o[a] < lo[a] || o[a] >= hi[a]) return false;
            continue;
        }
        float ta = (lo[a] - o[a]) / d[a];
        float tb = (hi[a] - o[a]) / d[a];
        t0 = max(t0, min(ta, tb));
        t1 = min(t1, max(ta, tb));
    }
    return t0 < t1;
}

// ---------------------------------------------------------------- 3D-DDA
struct GridWalk {
    vec3 o;        // ray origin relative to the grid origin (smaller numbers, less rounding)
    vec3 d;        // unit direction
    vec3 inv_d;    // 1 / d, 0 where d == 0 (those axes are never crossed)
    ivec3 step;
    ivec3 cell;    // current cell
    int axis;      // axis crossed when leaving the current cell
    float t_enter; // the current cell spans [t_enter, t_exit] of the ray
    float t_exit;
    float t_end;
};

void walk_find_exit(inout GridWalk w) {
    // Next boundaries are recomputed from the cell index each step, as on the CPU, so no
    // error accumulates along long rays; ties go to the lowest axis (numpy's argmin).
    vec3 boundary = (vec3(w.cell) + vec3(greaterThan(w.step, ivec3(0)))) * u_cell_size;
    vec3 t_next = (boundary - w.o) * w.inv_d;
    t_next = mix(t_next, vec3(BIG), equal(w.d, vec3(0.0)));
    w.axis = (t_next.x <= t_next.y && t_next.x <= t_next.z) ? 0 : (t_next.y <= t_next.z ? 1 : 2);
    w.t_exit = min(t_next[w.axis], w.t_end);
}

// Starts a walk of o + t d, t in [t_min, t_max], over the cells u_walk_lo..u_walk_hi.
// False when the ray misses them. The first cell is then w.cell.
bool walk_begin(vec3 origin, vec3 d, float t_min, float t_max, out GridWalk w) {
    w.o = origin - u_grid_origin;
    w.d = d;
    float t0 = t_min, t1 = t_max;
    vec3 lo = vec3(u_walk_lo) * u_cell_size;
    vec3 hi = vec3(u_walk_hi + 1) * u_cell_size;
    if (!ray_box(w.o, d, lo, hi, t0, t1)) return false;
    w.step = ivec3(mix(vec3(-1.0), vec3(1.0), greaterThan(d, vec3(0.0))));
    w.inv_d = mix(vec3(1.0) / mix(d, vec3(1.0), equal(d, vec3(0.0))), vec3(0.0), equal(d, vec3(0.0)));
    w.cell = clamp(ivec3(floor((w.o + t0 * d) / u_cell_size)), u_walk_lo, u_walk_hi);
    w.t_enter = t0;
    w.t_end = t1;
    walk_find_exit(w);
    return true;
}

// Moves to the next cell along the ray; false when the walk has ended.
bool walk_next(inout GridWalk w) {
    if (w.t_exit >= w.t_end) return false;
    w.cell[w.axis] += w.step[w.axis];
    if (w.cell[w.axis] < u_walk_lo[w.axis] || w.cell[w.axis] > u_walk_hi[w.axis]) return false;
    w.t_enter = w.t_exit;
    walk_find_exit(w);
    return true;
}

int walk_flat_cell(GridWalk w) {
    return w.cell.x + u_grid_dims.x * (w.cell.y + u_grid_dims.y * w.cell.z);
}

// ------------------------------------------------------- sphere queries
// Visibility (0..1) of the segment o + t d, t in [t_min, t_max], through the grid: the
// minimum over the spheres met (culled ones and skip_atom excluded; the probe sphere, which
// clipping never cuts, when with_probe). Hard when shell == (0, 0): stops at the first
// blocking sphere.
float trace_visibility(vec3 o, vec3 d, float t_min, float t_max, int skip_atom, vec2 shell,
                       float growth, bool with_probe) {
    float vis = 1.0;
    if (with_probe && u_probe_sphere.w > 0.0) {  // the probe is never clipped
        vis = occluder_visibility(o, d, t_min, t_max, u_probe_sphere, shell, growth);
        if (vis <= 0.0) return 0.0;
    }
    vec3 cut_normal;
    if (!clip_ray(o, d, t_min, t_max, cut_normal)) return vis;
    GridWalk w;
    if (!walk_begin(o, d, t_min, t_max, w)) return vis;
    do {
        int cell = walk_flat_cell(w);
        for (uint k = cell_start[cell]; k < cell_start[cell + 1]; ++k) {
            int atom = int(cell_atoms[k]);
            if (atom == skip_atom || (culled_flags(atom) & CULLED) != 0u) continue;
            vis = min(vis, occluder_visibility(o, d, t_min, t_max, grid_sphere(atom), shell, growth));
            if (vis <= 0.0) return 0.0;
        }
    } while (walk_next(w));
    return vis;
}

// Entry and exit t of the ray o + t d (d unit) into a sphere; false on a miss.
bool sphere_interval(vec3 o, vec3 d, vec4 sphere, out float t_in, out float t_out) {
    vec3 f = o - sphere.xyz;
    float b = dot(f, d);
    vec3 q = f - b * d;
    float disc = sphere.w * sphere.w - dot(q, q);
    if (disc < 0.0) return false;
    float h = sqrt(disc);
    t_in = -b - h;
    t_out = -b + h;
    return true;
}

// Closest visible surface along o + t d, t in [t_min, t_max]: a sphere, or a cap where a
// clip plane or the cube face cuts one; or the probe sphere (ATOM_PROBE, seen from outside,
// never clipped).
bool trace_closest(vec3 o, vec3 d, float t_min, float t_max, int skip_atom, bool with_probe,
                   out float t_hit, out int hit_atom, out vec3 hit_normal, out bool hit_cap) {
    t_hit = BIG;
    hit_atom = ATOM_BACKGROUND;
    hit_normal = vec3(0.0);
    hit_cap = false;
    float t_in, t_out;
    if (with_probe && u_probe_sphere.w > 0.0 && sphere_interval(o, d, u_probe_sphere, t_in, t_out)) {
        if (t_in >= t_min && t_in <= t_max) {  // the probe is never clipped
            t_hit = t_in;
            hit_atom = ATOM_PROBE;
            hit_normal = (o + t_in * d - u_probe_sphere.xyz) / u_probe_sphere.w;
        }
    }
    vec3 cut_normal;
    if (!clip_ray(o, d, t_min, t_max, cut_normal)) return hit_atom != ATOM_BACKGROUND;
    GridWalk w;
    if (walk_begin(o, d, t_min, min(t_max, t_hit), w)) {
        do {
            int cell = walk_flat_cell(w);
            for (uint k = cell_start[cell]; k < cell_start[cell + 1]; ++k) {
                int atom = int(cell_atoms[k]);
                if (atom == skip_atom || (culled_flags(atom) & CULLED) != 0u) continue;
                vec4 sphere = grid_sphere(atom);
                if (!sphere_interval(o, d, sphere, t_in, t_out)) continue;
                float t = max(t_in, t_min);
                if (t > min(t_out, t_max) || t >= t_hit) continue;
                t_hit = t;
                hit_atom = atom;
                hit_cap = t_in < t_min;
                hit_normal = hit_cap ? cut_normal : (o + t * d - sphere.xyz) / sphere.w;
            }
            // A sphere entered at t lies in the cell holding o + t d, and cells come in t
            // order: once a hit lies within the current cell no later cell can beat it.
            if (t_hit <= w.t_exit) break;
        } while (walk_next(w));
    }
    return hit_atom != ATOM_BACKGROUND;
}
