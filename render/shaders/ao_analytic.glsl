// Analytic ambient occlusion (Quilez's sphere occlusion, ao_sphere.glsl) from each atom's K
// nearest neighbours and the probe; occluders combine as prod(1 - occ_i), which never goes
// negative where neighbours overlap. Cost: K sphere terms per pixel, whatever the molecule.
// Run by ao_analytic.comp on every pixel, and by ao_analytic.frag on the surfaces a depth
// test picks. Pixels the lighting leaves alone are 1.
#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "ao_sphere.glsl"

#define MAX_K 32
// n_atoms x MAX_K atom ids, -1 padded: a table in an image (table_image.glsl)
layout(r32i, binding = 1) readonly uniform iimage2D u_ao_neighbours;

uniform int u_k;
uniform int u_probe_neighbours[MAX_K];  // atoms nearest the probe, for the probe's own pixels

float analytic_accessibility(ivec2 px) {
    vec3 p, n;
    int atom;
    float ao = 1.0;
    if (gbuffer_fetch(px, p, n, atom)) {
        if (atom >= 0) {
            for (int j = 0; j < u_k; ++j) ao *= neighbour_accessibility(p, n, imageLoad(u_ao_neighbours, table_texel(uint(atom * MAX_K + j))).x);
            if (u_probe_sphere.w > 0.0) ao *= 1.0 - probe_occlusion(p, n, u_probe_sphere, u_probe_reach);
        } else if (atom == ATOM_PROBE) {
            for (int j = 0; j < u_k; ++j) ao *= neighbour_accessibility(p, n, u_probe_neighbours[j]);
        }
    }
    return ao;
}
