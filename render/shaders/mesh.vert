#version 410 core
// Benchmark baseline: every atom as an instanced triangle-mesh sphere.
in vec3 in_vertex;   // unit-sphere vertex (also its normal)
in vec4 in_sphere;   // per instance: centre xyz, radius
in vec4 in_color;
in int in_atom;

#include "camera.glsl"

out MeshData {
    vec3 position;
    vec3 normal;
    flat vec3 color;
    flat int id;
} vs_out;

void main() {
    vec3 p = in_sphere.xyz + in_vertex * in_sphere.w;
    vs_out.position = p;
    vs_out.normal = in_vertex;
    vs_out.color = in_color.rgb;
    vs_out.id = in_atom;
    gl_Position = u_viewproj * vec4(p, 1.0);
}
