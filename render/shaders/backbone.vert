#version 410 core
// Backbone trace: C-alpha (or P) positions, two per segment (GL_LINES).
in vec3 in_position;
in vec3 in_color;
in int in_atom;

#include "line_blocks.glsl"
out LINE_VERTEX_BLOCK vs_out;

void main() {
    vs_out.position = in_position;
    vs_out.color = in_color;
    vs_out.id = in_atom;
}
