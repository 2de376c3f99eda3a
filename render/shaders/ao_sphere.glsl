// The analytic ambient occlusion of an atom's neighbours: the product of each one's
// accessibility, 1 - sphere_occlusion (occluders.glsl: Quilez's one-sphere occlusion).
// Neighbours are whole spheres: culled ones, and those whose centre is clipped away (see
// Culling.centre_clipped), are skipped. Needs grid_traversal.glsl.

float neighbour_accessibility(vec3 p, vec3 n, int other) {
    if (other < 0 || culled_flags(other) != 0u) return 1.0;
    return 1.0 - sphere_occlusion(p, n, grid_sphere(other));
}
