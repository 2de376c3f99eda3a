// The renderer's visibility buffer (render/gl/targets.py, RGBA32F) from the lighting terms:
// r directional-light visibility, g 1 (the probe light's visibility is a texture of its
// own, which the shading pass reads: render/passes/base.py ProbeLighting), b ambient
// accessibility, a edge cueing (contour lines, halos); the shading pass multiplies each
// into its term.
//
// The terms as given: on whole frames as traced, the probe among the occluders; on layered
// frames (the frame cache: render/passes/lighting.py) the molecule's own, computed
// without the probe. There the buffer keeps the molecule's terms, under the probe too: the
// shading pass colours the probe's own pixels without them, and takes what the probe does
// to the atoms' pixels — its shadow of the sun, its share of the AO (probe_share.glsl) —
// in itself. EXPORT (visibility_compose.comp) gives a layered frame's sun and ambient as a
// whole frame has them: the probe's own pixels bring theirs, the sun traced
// (u_probe_pixels_sun), the ambient the analytic occlusion of the atoms nearest the probe,
// and the atoms' pixels the probe's share.
// The value for one pixel is composed_visibility: drawn by visibility_compose.frag,
// computed by visibility_compose.comp for the export.

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "lights.glsl"
#include "ao_sphere.glsl"
#include "probe_share.glsl"

#define MAX_K 32
layout(binding = 3) uniform sampler2D u_shadow_dir;
layout(binding = 5) uniform sampler2D u_ambient;
layout(binding = 6) uniform sampler2D u_edges;
layout(binding = 7) uniform sampler2D u_probe_pixels_sun;
uniform int u_probe_sun;        // the probe's pixels bring their own sun
uniform int u_probe_ambient;    // the probe's pixels get the ambient of the atoms nearest it
uniform int u_k;
uniform int u_probe_neighbours[MAX_K];

// The visibility buffer's value at px; `sun_out` and `ambient_out` are its sun and its
// ambient, with EXPORT the probe's terms added.
vec4 composed_visibility(ivec2 px, out float sun_out, out float ambient_out) {
    float sun = texelFetch(u_shadow_dir, px, 0).r;
    float ambient = texelFetch(u_ambient, px, 0).r;
    sun_out = sun;
    ambient_out = ambient;
#ifdef EXPORT
    vec3 p, n;
    int atom;
    bool lit = gbuffer_fetch(px, p, n, atom);
    if (lit && atom == ATOM_PROBE) {
        if (u_probe_sun != 0) sun_out = texelFetch(u_probe_pixels_sun, px, 0).r;
        if (u_probe_ambient != 0) {
            ambient_out = 1.0;
            for (int j = 0; j < u_k; ++j) ambient_out *= neighbour_accessibility(p, n, u_probe_neighbours[j]);
        }
    } else if (lit && atom >= 0) {
        add_probe_share(p, n, sun_out, ambient_out);
    }
#endif
    return vec4(sun, 1.0, ambient, texelFetch(u_edges, px, 0).r);
}
