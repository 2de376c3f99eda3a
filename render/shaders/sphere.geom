#version 410 core
// Quad mode: one camera-facing square per sphere (see sphere_bound.glsl).
layout(points) in;
layout(triangle_strip, max_vertices = 4) out;

#include "camera.glsl"
#include "sphere_bound.glsl"

in VertexData {
    flat vec4 sphere;
    flat vec3 color;
    flat int id;
} gs_in[];

out VertexData {
    flat vec4 sphere;
    flat vec3 color;
    flat int id;
} gs_out;

void main() {
    vec3 corners[4];
    // The eye inside the sphere: every pixel's ray starts inside it, so cover the whole
    // view at the near plane (depth 0); the fragment shader caps it on the near plane.
    bool inside = sphere_quad(gs_in[0].sphere.xyz, gs_in[0].sphere.w, corners) == 0.0;
    for (int i = 0; i < 4; ++i) {
        gs_out.sphere = gs_in[0].sphere;
        gs_out.color = gs_in[0].color;
        gs_out.id = gs_in[0].id;
        gl_Position = inside ? vec4(float(i & 1) * 2.0 - 1.0, float(i >> 1) * 2.0 - 1.0, -1.0, 1.0)
                             : u_viewproj * vec4(corners[i], 1.0);
        EmitVertex();
    }
    EndPrimitive();
}
