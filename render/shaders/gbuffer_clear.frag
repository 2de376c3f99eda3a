#version 410 core
// Background values of every G-buffer attachment (an integer attachment cannot be
// cleared to -1 through the float clear colour).
#include "gbuffer_out.glsl"

void main() {
    o_albedo = vec4(0.0);
    o_position = vec4(0.0);
    o_normal = vec4(0.0);
    o_ids = ivec2(ATOM_BACKGROUND, KIND_BACKGROUND);
}
