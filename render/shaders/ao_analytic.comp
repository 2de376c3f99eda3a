#version 430 core
// Analytic ambient occlusion (Quilez's sphere occlusion, ao_sphere.glsl) from each atom's K
// nearest neighbours and the probe; occluders combine as prod(1 - occ_i), which never goes
// negative where neighbours overlap. Cost: K sphere terms per pixel, whatever the molecule.
layout(local_size_x = 8, local_size_y = 8) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "ao_sphere.glsl"

#define MAX_K 32
layout(std430, binding = 4) readonly buffer Neighbours { int neighbours[]; };  // n_atoms x MAX_K, -1 padded
layout(r32f, binding = 0) uniform writeonly image2D u_accessibility;

uniform int u_k;
uniform int u_probe_neighbours[MAX_K];  // atoms nearest the probe, for the probe's own pixels

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_accessibility)))) return;
    vec3 p, n;
    int atom;
    float ao = 1.0;
    if (gbuffer_fetch(px, p, n, atom)) {
        if (atom >= 0) {
            for (int j = 0; j < u_k; ++j) ao *= neighbour_accessibility(p, n, neighbours[atom * MAX_K + j]);
            if (u_probe_sphere.w > 0.0) ao *= 1.0 - probe_occlusion(p, n, u_probe_sphere, u_probe_reach);
        } else if (atom == ATOM_PROBE) {
            for (int j = 0; j < u_k; ++j) ao *= neighbour_accessibility(p, n, u_probe_neighbours[j]);
        }
    }
    imageStore(u_accessibility, px, vec4(ao));
}
