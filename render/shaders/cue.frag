#version 410 core
#include "constants.glsl"
// Probe cues (outline, ghost tip, spring, force arrow): the vertex colour at an opacity.
#include "line_blocks.glsl"
in LINE_FRAGMENT_BLOCK fs_in;

uniform float u_alpha;
uniform int u_hidden_only;  // 1: only where the G-buffer shows something other than the probe
uniform isampler2D u_ids;   // the G-buffer's (atom id, kind)
out vec4 o_color;

void main() {
    if (u_hidden_only == 1 && texelFetch(u_ids, ivec2(gl_FragCoord.xy), 0).r == ATOM_PROBE) discard;
    o_color = vec4(fs_in.color, u_alpha);
}
