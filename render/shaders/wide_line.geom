#version 410 core
// A line segment widened into a screen-space quad: at least u_min_width_px wide, wider
// when the world radius u_radius projects larger. The world position varying stays on
// the segment's centre line; `across` runs -1..1 over the width (for tube shading).
layout(lines) in;
layout(triangle_strip, max_vertices = 4) out;

#include "camera.glsl"

uniform float u_radius;        // Å
uniform float u_min_width_px;  // pixels
uniform float u_proj_scale;    // P[1][1] * viewport height / 2: pixels per Å at view depth 1

#include "line_blocks.glsl"
in LINE_VERTEX_BLOCK gs_in[];
out LINE_FRAGMENT_BLOCK gs_out;

void main() {
    vec4 c0 = u_viewproj * vec4(gs_in[0].position, 1.0);
    vec4 c1 = u_viewproj * vec4(gs_in[1].position, 1.0);
    if (c0.w <= 0.0 || c1.w <= 0.0) return;  // behind the eye
    vec2 s0 = c0.xy / c0.w * u_viewport.zw * 0.5;
    vec2 s1 = c1.xy / c1.w * u_viewport.zw * 0.5;
    vec2 dir = s1 - s0;
    if (dot(dir, dir) < 1e-12) dir = vec2(1.0, 0.0);
    dir = normalize(dir);
    vec2 nrm = vec2(-dir.y, dir.x);
    vec3 tangent = normalize(gs_in[1].position - gs_in[0].position + 1e-12);
    vec4 clips[2] = vec4[2](c0, c1);
    for (int i = 0; i < 2; ++i) {
        float half_px = max(u_radius * u_proj_scale / clips[i].w, 0.5 * u_min_width_px);
        vec2 offset = nrm * half_px / (u_viewport.zw * 0.5) * clips[i].w;
        for (int side = -1; side <= 1; side += 2) {
            gs_out.position = gs_in[i].position;
            gs_out.color = gs_in[i].color;
            gs_out.across = float(side);
            gs_out.tangent = tangent;
            gs_out.along = float(i);
            gs_out.ends = ivec2(gs_in[0].id, gs_in[1].id);
            gl_Position = vec4(clips[i].xy + float(side) * offset, clips[i].zw);
            EmitVertex();
        }
    }
    EndPrimitive();
}
