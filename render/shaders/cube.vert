#version 410 core
// Navigation-cube wire: the unit cube's 12 edges, scaled and moved to the cube.
in vec3 in_position;  // corners of [-1, 1]^3
uniform vec4 u_cube;       // centre xyz, half edge (Å)
uniform mat3 u_cube_axes;  // the cube's axes (columns) in the world frame

#include "line_blocks.glsl"
out LINE_VERTEX_BLOCK vs_out;

void main() {
    vs_out.position = u_cube.xyz + u_cube_axes * in_position * u_cube.w;
    vs_out.color = vec3(0.0);
    vs_out.id = -1;
}
