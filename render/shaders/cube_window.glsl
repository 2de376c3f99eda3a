// Whether a pixel's eye ray meets the navigation cube: the cube is a window, only what is
// in it shows through it. The backbone trace is drawn only where the ray misses the cube,
// and the atoms, cut to the cube, only where it meets it, so the two never share a pixel
// (backbone.frag, gbuffer_clear.frag CUBE_WINDOW).
uniform vec4 u_cube;       // centre xyz, half edge (Å)
uniform mat3 u_cube_axes;  // the cube's axes (columns) in the world frame

// Whether the ray o + t d (t >= 0) meets the cube (slabs in the cube's own frame).
bool ray_meets_cube(vec3 o, vec3 d) {
    vec3 ol = transpose(u_cube_axes) * (o - u_cube.xyz);
    vec3 dl = transpose(u_cube_axes) * d;
    float t0 = 0.0, t1 = 1e30;
    for (int a = 0; a < 3; ++a) {
        if (abs(dl[a]) < 1e-12) {
            if (abs(ol[a]) > u_cube.w) return false;
            continue;
        }
        float ta = (-u_cube.w - ol[a]) / dl[a];
        float tb = (u_cube.w - ol[a]) / dl[a];
        t0 = max(t0, min(ta, tb));
        t1 = min(t1, max(ta, tb));
    }
    return t0 <= t1;
}
