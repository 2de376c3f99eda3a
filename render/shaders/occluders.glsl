// What one sphere takes from a surface point's light, as pure functions of the geometry
// (no buffers: the shading pass, GL 4.1, uses them too): the shadow rays' occluder test
// and Quilez's analytic sphere occlusion (ao_sphere.glsl has its neighbour loop).

// Visibility of one occluder seen along the segment o + t d, t in [t0, t1] (d unit), after
// Parker et al. 1998: with b the distance from the centre to the segment, 0 inside the
// inner sphere, 1 outside the outer one, smoothstep between. shell = (inner, outer) offsets
// from the vdW radius in Å; growth > 0 widens the shell linearly from 0 at the receiver to
// full at distance `growth` (penumbrae grow with occluder-receiver distance, and atoms
// touching the receiver do not darken it). shell = (0, 0) is the hard shadow test.
float occluder_visibility(vec3 o, vec3 d, float t0, float t1, vec4 sphere, vec2 shell, float growth) {
    vec3 f = sphere.xyz - o;
    float t = clamp(dot(f, d), t0, t1);
    vec3 q = f - t * d;  // closest approach, the stable form (Haines et al., RTG ch. 7)
    float b = length(q);
#ifdef HARD_SHADOWS  // shell (0, 0): what the lines below give then, without the shell's arithmetic
    return b < sphere.w ? 0.0 : 1.0;
#endif
    float s = growth > 0.0 ? clamp(t / growth, 0.0, 1.0) : 1.0;
    float r_in = max(sphere.w + shell.x * s, 0.0);
    float r_out = sphere.w + shell.y * s;
    if (b < r_in) return 0.0;
    if (b >= r_out) return 1.0;
    return smoothstep(r_in, r_out, b);
}

// Quilez's sphere occlusion: one sphere of radius r at distance l, at angle theta from the
// normal, occludes cos(theta) (r / l)^2 of the cosine-weighted hemisphere (exact while it
// lies wholly above the horizon).
float sphere_occlusion(vec3 p, vec3 n, vec4 sphere) {
    vec3 to_centre = sphere.xyz - p;
    float l = length(to_centre);
    return clamp(max(dot(n, to_centre) / l, 0.0) * (sphere.w / l) * (sphere.w / l), 0.0, 1.0);
}

// The probe's share of the ambient occlusion: its sphere occlusion windowed to 0 at
// `reach` Å from its centre by (1 - (l/reach)^4)^2, its light's window (lights.glsl), so
// that nothing the probe does to the picture reaches farther than its light (a frame in
// which only the probe moved is shaded only there: render/passes/shading.py).
float probe_occlusion(vec3 p, vec3 n, vec4 probe, float reach) {
    float x = distance(probe.xyz, p) / reach;
    float window = clamp(1.0 - x * x * x * x, 0.0, 1.0);
    return sphere_occlusion(p, n, probe) * window * window;
}

