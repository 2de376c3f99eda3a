#version 410 core
// Navigation-cube wire colour, depth-tested against the G-buffer.
#include "line_blocks.glsl"
in LINE_FRAGMENT_BLOCK fs_in;

uniform vec4 u_wire_color;
out vec4 o_color;

void main() {
    o_color = u_wire_color;
}
