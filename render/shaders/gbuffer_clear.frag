#version 410 core
// The background's ids (an integer attachment cannot be cleared to -1 through the float
// clear colour, and moderngl has no integer clear): drawn into the ids attachment alone,
// the float attachments and the depth are cleared (render/passes/clear.py).
#include "constants.glsl"

layout(location = 0) out ivec2 o_ids;

void main() {
    o_ids = ivec2(ATOM_BACKGROUND, KIND_BACKGROUND);
}
