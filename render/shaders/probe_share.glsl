// The probe's share of an atom pixel's light on a layered frame (the frame cache,
// render/passes/lighting.py): the molecule's terms are kept without the probe, and
// here the probe's are taken in, as the whole frame's trace takes the probe among the
// occluders —
// - its shadow of the sun: the minimum of the molecule's visibility and the probe
//   sphere's along the same ray (occluder_visibility, the trace's own test);
// - its share of the ambient occlusion: the molecule's accessibility times 1 - the
//   analytic occlusion of the one probe sphere, windowed at its reach (probe_occlusion),
//   as ao_analytic.glsl multiplies it in on whole frames.
// The shading pass applies them: the ambient share reaches every pixel within the probe
// light's range, where the shading runs anyway, and the lighting adds the pixels the
// shadow can fall on to what it shades again. visibility_compose.comp does too, for the
// export.
#include "occluders.glsl"
#include "ray_origin.glsl"

uniform int u_probe_share_ambient;  // the probe's share of the ambient occlusion
uniform int u_probe_share_sun;      // the probe's shadow of the sun
uniform vec4 u_share_probe;         // the probe sphere: centre (Å), radius
uniform float u_share_probe_reach;  // Å: where its share of the ambient occlusion ends
uniform vec3 u_share_sun_dir;       // towards the sun, unit (lights.glsl u_sun_dir)
uniform vec2 u_share_shell;         // the sun's soft-shadow shell and its growth (shadows.comp)
uniform float u_share_shell_growth;

void add_probe_share(vec3 p, vec3 n, inout float sun, inout float ambient) {
    if (u_probe_share_sun != 0 && sun > 0.0)  // the ray as the trace has it, to BIG (grid_traversal.glsl)
        sun = min(sun, occluder_visibility(ray_origin(p, n), u_share_sun_dir, 0.0, 1e30, u_share_probe,
                                           u_share_shell, u_share_shell_growth));
    if (u_probe_share_ambient != 0) ambient *= 1.0 - probe_occlusion(p, n, u_share_probe, u_share_probe_reach);
}
