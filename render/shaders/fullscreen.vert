#version 410 core
// One triangle that covers the viewport (no vertex buffer: gl_VertexID 0..2). With
// AT_FAR_PLANE it lies at depth 1, the G-buffer's clear value, so that a depth test against
// the G-buffer picks its background (EQUAL) or its surfaces (GREATER) before the fragment
// shader runs: llvmpipe runs a shader's branches whether taken or not, and skips only the
// blocks of pixels the depth test rejects.
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
#ifdef AT_FAR_PLANE
    gl_Position = vec4(p * 2.0 - 1.0, 1.0, 1.0);
#else
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
#endif
}
