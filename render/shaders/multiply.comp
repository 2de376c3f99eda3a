#version 430 core
// out = a * b per pixel (the hybrid AO: analytic x ray-traced).
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 3) uniform sampler2D u_a;
layout(binding = 4) uniform sampler2D u_b;
layout(r32f, binding = 0) uniform writeonly image2D u_out;
void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_out)))) return;
    imageStore(u_out, px, vec4(texelFetch(u_a, px, 0).r * texelFetch(u_b, px, 0).r));
}
