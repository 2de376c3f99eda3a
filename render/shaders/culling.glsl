// The culling on the GPU (render/lighting/culling.py Culling): what is drawn is the spheres
// intersected with the kept half-spaces of the clip planes and the navigation cube (an
// axis-aligned box); for the programs that clip rays or points without walking the grid.
#include "constants.glsl"
uniform int u_clip_count;
uniform vec4 u_clip_planes[MAX_CLIP_PLANES];  // kept where dot(xyz, p) + w >= 0
uniform int u_cube_on;
uniform vec3 u_cube_lo;
uniform vec3 u_cube_hi;

// The kept part [t0, t1] of the ray after the clip planes and the navigation cube, and the
// outward normal of the cut the ray enters through (zero when it starts inside).
// Compiled with NO_CLIPPING (nothing is cut away), it only checks the interval, and with
// NO_CUBE (no cube box: none, or its faces among the planes) it leaves the box out: llvmpipe
// runs a shader's every instruction whichever way a branch goes, uniform ones included.
bool clip_ray(vec3 o, vec3 d, inout float t0, inout float t1, out vec3 entry_normal) {
    entry_normal = vec3(0.0);
#ifndef NO_CLIPPING
    for (int i = 0; i < u_clip_count; ++i) {
        vec4 plane = u_clip_planes[i];
        float s = dot(plane.xyz, o) + plane.w;
        float dn = dot(plane.xyz, d);
        if (dn > 0.0) {
            float t = -s / dn;
            if (t > t0) { t0 = t; entry_normal = -plane.xyz; }
        } else if (dn < 0.0) {
            t1 = min(t1, -s / dn);
        } else if (s < 0.0) {
            return false;
        }
    }
#ifndef NO_CUBE
    if (u_cube_on != 0) {
        for (int a = 0; a < 3; ++a) {
            if (d[a] == 0.0) {
                if (o[a] < u_cube_lo[a] || o[a] > u_cube_hi[a]) return false;
                continue;
            }
            float ta = (u_cube_lo[a] - o[a]) / d[a];
            float tb = (u_cube_hi[a] - o[a]) / d[a];
            float t_in = min(ta, tb);
            if (t_in > t0) {
                t0 = t_in;
                entry_normal = vec3(0.0);
                entry_normal[a] = d[a] > 0.0 ? -1.0 : 1.0;
            }
            t1 = min(t1, max(ta, tb));
        }
    }
#endif
#endif
    return t0 < t1;
}

// Whether a point is cut away (behind a clip plane, or outside the navigation cube): no
// sphere is drawn there.
bool point_cut(vec3 p) {
#ifndef NO_CLIPPING
    for (int i = 0; i < u_clip_count; ++i)
        if (dot(u_clip_planes[i].xyz, p) + u_clip_planes[i].w < 0.0) return true;
    if (u_cube_on != 0 && (any(lessThan(p, u_cube_lo)) || any(greaterThan(p, u_cube_hi)))) return true;
#endif
    return false;
}
