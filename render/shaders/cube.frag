#version 410 core
// Navigation-cube wire colour, depth-tested against the G-buffer.
in LineFragment {
    vec3 position;
    vec3 color;
    float across;
    float along;
    flat vec3 tangent;
    flat ivec2 ends;
} fs_in;

uniform vec4 u_wire_color;
out vec4 o_color;

void main() {
    o_color = u_wire_color;
}
