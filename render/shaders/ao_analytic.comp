#version 430 core
// Analytic ambient occlusion (Quilez's sphere occlusion) from each atom's K nearest
// neighbours and the probe. One sphere of radius r at distance l, at angle theta from the
// normal, occludes cos(theta) (r / l)^2 of the cosine-weighted hemisphere (exact while it
// lies wholly above the horizon); occluders combine as prod(1 - occ_i), which never goes
// negative where neighbours overlap. Cost: K sphere terms per pixel, whatever the molecule.
// Neighbours are whole spheres: culled ones, and those whose centre is clipped away (see
// Culling.centre_clipped), are skipped.
layout(local_size_x = 8, local_size_y = 8) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"

#define MAX_K 32
layout(std430, binding = 4) readonly buffer Neighbours { int neighbours[]; };  // n_atoms x MAX_K, -1 padded
layout(r32f, binding = 0) uniform writeonly image2D u_accessibility;

uniform int u_k;
uniform int u_probe_neighbours[MAX_K];  // atoms nearest the probe, for the probe's own pixels

float sphere_occlusion(vec3 p, vec3 n, vec4 sphere) {
    vec3 to_centre = sphere.xyz - p;
    float l = length(to_centre);
    return clamp(max(dot(n, to_centre) / l, 0.0) * (sphere.w / l) * (sphere.w / l), 0.0, 1.0);
}

float neighbour_accessibility(vec3 p, vec3 n, int other) {
    if (other < 0 || culled[other] != 0u) return 1.0;
    return 1.0 - sphere_occlusion(p, n, spheres[other]);
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_accessibility)))) return;
    vec3 p, n;
    int atom;
    float ao = 1.0;
    if (gbuffer_fetch(px, p, n, atom)) {
        if (atom >= 0) {
            for (int j = 0; j < u_k; ++j) ao *= neighbour_accessibility(p, n, neighbours[atom * MAX_K + j]);
            if (u_probe_sphere.w > 0.0) ao *= 1.0 - sphere_occlusion(p, n, u_probe_sphere);
        } else if (atom == ATOM_PROBE) {
            for (int j = 0; j < u_k; ++j) ao *= neighbour_accessibility(p, n, u_probe_neighbours[j]);
        }
    }
    imageStore(u_accessibility, px, vec4(ao));
}
