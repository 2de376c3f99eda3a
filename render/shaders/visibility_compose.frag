#version 430 core
// The visibility buffer from the lighting terms (visibility_terms.glsl), drawn at the far
// plane (fullscreen.vert AT_FAR_PLANE) over the pixels the lighting composes (a fragment
// pass runs faster there than a compute pass on llvmpipe).
#include "visibility_terms.glsl"

layout(location = 0) out vec4 o_visibility;

void main() {
    float sun, ambient;
    o_visibility = composed_visibility(ivec2(gl_FragCoord.xy), sun, ambient);
}
