// Clipping planes: a point x is kept where dot(plane.xyz, x) + plane.w >= 0 (world frame,
// unit normals). The list holds the user's planes, the probe plane, the navigation cube's
// six faces and the camera's near plane, as the CPU sends them.
#include "constants.glsl"
uniform vec4 u_planes[MAX_CLIP_PLANES];
uniform int u_n_planes;

// Cut the ray interval [t0, t1] of o + t d with every plane's kept half-space.
// Returns false when nothing is left; `plane` is the index of the plane that moved the
// entry point (-1 when the entry is the original one, i.e. no cap).
bool clip_interval(vec3 o, vec3 d, inout float t0, inout float t1, out int plane) {
    plane = -1;
    for (int i = 0; i < u_n_planes; ++i) {
        vec4 pl = u_planes[i];
        float dn = dot(pl.xyz, d);
        float s = dot(pl.xyz, o) + pl.w;  // signed distance of the ray origin
        if (dn == 0.0) {
            if (s < 0.0) return false;  // parallel and wholly on the removed side
            continue;
        }
        float tp = -s / dn;  // where the ray crosses the plane
        if (dn > 0.0) {      // entering the kept side at tp
            if (tp > t0) { t0 = tp; plane = i; }
        } else {             // leaving the kept side at tp
            t1 = min(t1, tp);
        }
    }
    return t0 <= t1;
}

// Whether a point is on the kept side of every plane (for lines, which have no caps).
bool point_kept(vec3 p) {
    for (int i = 0; i < u_n_planes; ++i)
        if (dot(u_planes[i].xyz, p) + u_planes[i].w < 0.0) return false;
    return true;
}
