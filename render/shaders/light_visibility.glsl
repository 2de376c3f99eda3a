// A surface point's visibility of a light (light_visibility): hard shadows, or Parker soft
// shadows from the same single ray (u_shell = (inner, outer) offsets, see
// occluder_visibility). Directional light: the ray runs to the grid's (or the navigation
// cube's) edge. Probe point light: the segment ends at the light; points beyond its
// attenuation radius are not traced (1), and the probe sphere holding the light does not
// occlude it. Points facing away from the light are 0: their own atom blocks it. Points the
// lighting leaves alone are 1. With LIGHT_BUFFER the probe light's rays go through its light
// buffer (light_buffer.glsl) and nothing else; with SUN_BUFFER the directional light's
// through its own (sun_buffer.glsl): llvmpipe runs every instruction of a shader for each
// group of pixels, whichever way they branch, so the walk is left out of them. Traced per
// G-buffer pixel by shadow_pixel.glsl, and by the shading pass itself (shading_traced.frag).
#include "grid_traversal.glsl"
#include "ray_origin.glsl"
#include "lights.glsl"
#ifdef LIGHT_BUFFER
#include "light_buffer.glsl"
#endif
#ifdef SUN_BUFFER
#include "sun_buffer.glsl"
#endif

uniform int u_point_light;     // 0: the directional light, 1: the probe's point light
uniform vec2 u_shell;
uniform float u_shell_growth;

float light_visibility(bool lit, vec3 p, vec3 n, int atom) {
    float vis = 1.0;
    if (lit) {
        vec3 o = ray_origin(p, n);
        vec3 d = u_sun_dir;
        float t_max = BIG;
        bool traced = true;
        if (u_point_light != 0) {
            vec3 to_light = u_probe_light_pos - o;
            t_max = length(to_light);
            d = to_light / max(t_max, 1e-30);
            traced = distance(u_probe_light_pos, p) <= u_probe_light_radius;
        }
        if (traced) {
            vis = dot(n, d) > 0.0
#if defined(LIGHT_BUFFER)
                ? trace_point_visibility(o, u_probe_light_pos, atom, u_shell, u_shell_growth)
#elif defined(SUN_BUFFER)
                ? trace_sun_visibility(o, d, atom, u_shell, u_shell_growth, atom != ATOM_PROBE)
#else
                ? trace_visibility(o, d, 0.0, t_max, atom, u_shell, u_shell_growth,
                                   u_point_light == 0 && atom != ATOM_PROBE)
#endif
                : 0.0;
        }
    }
    return vis;
}
