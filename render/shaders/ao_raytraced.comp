#version 430 core
// Ray-traced ambient occlusion through the grid: cosine-weighted rays of length
// u_distance from each pixel (any hit ends a ray), accumulated as a running mean over
// frames while the view is still. Sample i of a pixel is the i-th point of a per-pixel
// shifted R2 sequence, so samples of later frames fill the gaps of earlier ones.
layout(local_size_x = 8, local_size_y = 8) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "sampling.glsl"

layout(r32f, binding = 0) uniform image2D u_accessibility;  // running mean, read and written

uniform uint u_first_sample;  // samples already in u_accessibility
uniform int u_spp;            // samples this frame
uniform float u_distance;     // Å
uniform uint u_seed;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_accessibility)))) return;
    vec3 p, n;
    int atom;
    if (!gbuffer_fetch(px, p, n, atom)) {
        imageStore(u_accessibility, px, vec4(1.0));
        return;
    }
    vec3 o = ray_origin(p, n);
    uint seed = pixel_seed(px, u_seed);
    float visible = 0.0;
    for (int s = 0; s < u_spp; ++s) {
        vec3 d = cosine_direction(n, r2_sample(u_first_sample + uint(s), seed));
        visible += trace_visibility(o, d, 0.0, u_distance, atom, vec2(0.0), 0.0, atom != ATOM_PROBE);
    }
    float before = u_first_sample > 0u ? imageLoad(u_accessibility, px).r * float(u_first_sample) : 0.0;
    imageStore(u_accessibility, px, vec4((before + visible) / float(u_first_sample + uint(u_spp))));
}
