#version 410 core
// Screen-space triangles given in normalised device coordinates (the off-screen probe arrow).
in vec2 in_ndc;

void main() {
    gl_Position = vec4(in_ndc, 0.0, 1.0);
}
