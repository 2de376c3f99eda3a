// The probe's share of an atom pixel's ambient occlusion on a layered frame (the frame
// cache, render/passes/lighting_layers.py): the molecule's accessibility is kept without
// the probe and multiplied here by 1 - the analytic occlusion of the one probe sphere,
// windowed at its reach (probe_occlusion), as ao_analytic.glsl multiplies it in on whole
// frames. The shading pass applies it (it reaches every pixel within the probe light's
// range, where the shading runs anyway); visibility_compose.comp too, for the export.
// (The probe's shadow of the sun, a hard edge, is taken in by visibility_compose.comp,
// a compute program as the whole frame's trace is, so that both round alike.)
#include "occluders.glsl"

uniform int u_probe_share_ambient;  // the probe's share of the ambient occlusion
uniform vec4 u_share_probe;         // the probe sphere: centre (Å), radius
uniform float u_share_probe_reach;  // Å: where its share of the ambient occlusion ends

void add_probe_share(vec3 p, vec3 n, inout float ambient) {
    if (u_probe_share_ambient != 0) ambient *= 1.0 - probe_occlusion(p, n, u_share_probe, u_share_probe_reach);
}
