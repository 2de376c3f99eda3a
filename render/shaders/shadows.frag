#version 430 core
// Light visibility per G-buffer pixel (shadow_pixel.glsl), drawn into an r32f target over
// the G-buffer's surfaces only: the pass draws at the far plane (fullscreen.vert
// AT_FAR_PLANE) with a depth test, so that background pixels, which the pass clears to 1,
// run no shader at all (llvmpipe would pay for the trace's code in them whether they branch
// past it or not).
#include "shadow_pixel.glsl"

layout(location = 0) out vec4 o_visibility;

void main() {
    vec3 p, n;
    int atom;
    bool lit = gbuffer_fetch(ivec2(gl_FragCoord.xy), p, n, atom);
    o_visibility = vec4(light_visibility(lit, p, n, atom));
}
