#version 430 core
// The visibility buffer from the lighting terms (visibility_terms.glsl), drawn at the far
// plane (fullscreen.vert AT_FAR_PLANE) through a depth test against the G-buffer: on a
// layered frame the plain program for the background, the layered one for the surfaces,
// so that background pixels skip the layered program's G-buffer reads and probe terms
// (llvmpipe runs a shader's branches whether taken or not); on a whole frame the plain
// program for every pixel (a fragment pass runs faster there than the compute pass).
#include "visibility_terms.glsl"

layout(location = 0) out vec4 o_visibility;

void main() {
    float sun, ambient;
    o_visibility = composed_visibility(ivec2(gl_FragCoord.xy), sun, ambient);
}
