// Shadow rays of the probe's point light through its light buffer
// (render/lighting/light_buffer.py): the ray from o to the light tests the atoms listed
// for its direction seen from the light, nearest first, and stops at the first too far
// from the lists' centre to reach the ray (the light lies within the lists' slack of it).
// The same occluders and the same minimum as trace_visibility (grid_traversal.glsl,
// included before this): the lists are complete. The lists lie one after another in two
// tables (table_image.glsl): image 2 holds entry k's sphere at k; image 3 first each
// cell's first entry (u_lb_cells of them, then the number of entries: the last cell's
// end), then entry k's atom at u_lb_cells + 1 + k. (Images: llvmpipe reads a storage
// buffer lane by lane.)
#include "table_image.glsl"
layout(rgba32f, binding = 2) readonly uniform image2D u_list_spheres;  // centre, vdW radius
layout(r32i, binding = 3) readonly uniform iimage2D u_list_atoms;

uniform uint u_lb_cells;

uniform int u_lb_face_cells;
uniform vec3 u_lb_centre;      // where the lists were built for (the light lies within their slack of it)
uniform float u_lb_reach_pad;  // the shell's outer offset, the margin and the slack the lists were built with

// The cube cell holding direction v: face 2 axis + (v negative), i and j along the next
// two axes (cell_cones in light_buffer.py).
uint light_cell(vec3 v) {
    vec3 a = abs(v);
    int axis = (a.x >= a.y && a.x >= a.z) ? 0 : (a.y >= a.z ? 1 : 2);
    float major = a[axis];
    vec2 st = vec2(v[(axis + 1) % 3], v[(axis + 2) % 3]) / max(major, 1e-30);
    ivec2 ij = clamp(ivec2(floor((st * 0.5 + 0.5) * float(u_lb_face_cells))), ivec2(0), ivec2(u_lb_face_cells - 1));
    int face = 2 * axis + (v[axis] < 0.0 ? 1 : 0);
    return uint((face * u_lb_face_cells + ij.y) * u_lb_face_cells + ij.x);
}

float trace_point_visibility(vec3 o, vec3 light, int skip_atom, vec2 shell, float growth) {
    vec3 to_light = light - o;
    float t_max = length(to_light);
    vec3 d = to_light / max(t_max, 1e-30);
    uint cell = light_cell(o - light);
    uint first = uint(imageLoad(u_list_atoms, table_texel(cell)).x);
    uint end = uint(imageLoad(u_list_atoms, table_texel(cell + 1u)).x);
    float reach = t_max + u_lb_reach_pad;
    float t0 = 0.0, t1 = t_max;
    vec3 cut_normal;
    if (!clip_ray(o, d, t0, t1, cut_normal)) return 1.0;
    float vis = 1.0;
    // Two entries a turn, one exit: llvmpipe pays for every turn and every exit of a loop
    // in each group of pixels. An entry past `end` is the next list's and is not counted;
    // one beyond the reach darkens nothing (its distance to the ray exceeds its shell), so
    // testing it before the loop ends leaves the minimum as it is.
    for (uint k = first; k < end; k += 2u) {
        bool beyond = false;
        for (uint i = 0u; i < 2u; ++i) {  // unrolled
            uint j = k + i;
            vec4 sphere = imageLoad(u_list_spheres, table_texel(j));
            bool listed = j < end && imageLoad(u_list_atoms, table_texel(u_lb_cells + 1u + j)).x != skip_atom;
            float v = occluder_visibility(o, d, t0, t1, sphere, shell, growth);
            vis = listed ? min(vis, v) : vis;
            vec3 from_centre = sphere.xyz - u_lb_centre;
            float farthest = reach + sphere.w;
            beyond = beyond || dot(from_centre, from_centre) > farthest * farthest;  // this one and every later one
        }
        if (beyond || vis <= 0.0) break;
    }
    return vis;
}
