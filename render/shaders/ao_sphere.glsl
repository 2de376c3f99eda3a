// Quilez's sphere occlusion: one sphere of radius r at distance l, at angle theta from the
// normal, occludes cos(theta) (r / l)^2 of the cosine-weighted hemisphere (exact while it
// lies wholly above the horizon). Neighbours are whole spheres: culled ones, and those whose
// centre is clipped away (see Culling.centre_clipped), are skipped. Needs grid_traversal.glsl.

float sphere_occlusion(vec3 p, vec3 n, vec4 sphere) {
    vec3 to_centre = sphere.xyz - p;
    float l = length(to_centre);
    return clamp(max(dot(n, to_centre) / l, 0.0) * (sphere.w / l) * (sphere.w / l), 0.0, 1.0);
}

float neighbour_accessibility(vec3 p, vec3 n, int other) {
    if (other < 0 || culled[other] != 0u) return 1.0;
    return 1.0 - sphere_occlusion(p, n, spheres[other]);
}
