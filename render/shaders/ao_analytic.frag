#version 430 core
// Analytic ambient occlusion per G-buffer pixel (ao_analytic.glsl), drawn into an r32f
// target over the surfaces a depth test picks (render/gl/depth_picked.py; the background
// is cleared to 1).
#include "ao_analytic.glsl"

layout(location = 0) out vec4 o_accessibility;

void main() {
    o_accessibility = vec4(analytic_accessibility(ivec2(gl_FragCoord.xy)));
}
