#version 430 core
// QuteMol's edge cueing (Tarini et al. 2006) as an image-space factor the final colour is
// multiplied by (1 = untouched), from the G-buffer's view depths (background = infinitely
// far). Only neighbours showing another atom count, so a sphere's own curvature never
// draws lines or halos on it:
//   contour lines: a pixel with a neighbour within u_line_width pixels that lies more than
//     u_line_threshold Å in front of it is darkened, fully once the jump reaches twice the
//     threshold, so lines trace depth discontinuities (silhouettes, overlaps) and grow
//     stronger with the jump, not with the colour or the shading;
//   halos: a pixel behind a nearer surface within u_halo_radius pixels is shadowed by a
//     halo that fades with screen distance and grows with the depth gap (full at
//     u_halo_depth Å), so nearer parts stand out from what lies behind them.
// The pass may cover a rectangle only (u_offset: its first pixel).
layout(local_size_x = 8, local_size_y = 8) in;

#include "gbuffer_input.glsl"
#include "camera_input.glsl"

layout(r32f, binding = 0) uniform writeonly image2D u_edges;

uniform int u_contours;
uniform float u_line_width;      // pixels
uniform float u_line_threshold;  // Å
uniform int u_halos;
uniform float u_halo_radius;     // pixels
uniform float u_halo_depth;      // Å
uniform float u_halo_strength;
uniform ivec2 u_offset;

float depth_at(ivec2 q) {
    if (!gbuffer_lit(q)) return BIG_DEPTH;
    return view_depth(texelFetch(u_gb_position, q, 0).xyz);
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy) + u_offset;
    ivec2 size = imageSize(u_edges);
    if (any(greaterThanEqual(px, size))) return;
    float depth = depth_at(px);
    int atom = texelFetch(u_gb_ids, px, 0).r;
    float reach = max(u_contours != 0 ? u_line_width : 0.0, u_halos != 0 ? u_halo_radius : 0.0);
    int r = int(ceil(reach));
    float line = 0.0, halo = 0.0;
    for (int dy = -r; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
            ivec2 q = px + ivec2(dx, dy);
            if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
            float dist = length(vec2(dx, dy));
            float front = depth_at(q);
            if (front >= BIG_DEPTH || texelFetch(u_gb_ids, q, 0).r == atom) continue;
            float gap = depth >= BIG_DEPTH ? BIG_DEPTH : depth - front;
            if (u_contours != 0 && dist <= u_line_width && gap > u_line_threshold) {
                line = max(line, clamp(gap / u_line_threshold - 1.0, 0.0, 1.0));
            }
            if (u_halos != 0 && dist <= u_halo_radius && gap > 0.0) {
                halo = max(halo, (1.0 - dist / u_halo_radius) * clamp(gap / u_halo_depth, 0.0, 1.0));
            }
        }
    }
    imageStore(u_edges, px, vec4((1.0 - line) * (1.0 - u_halo_strength * halo)));
}
