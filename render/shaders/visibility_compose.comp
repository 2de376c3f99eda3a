#version 430 core
// The renderer's visibility buffer (render/gl/targets.py, RGBA16F) from the lighting terms:
// r directional-light visibility, g probe-light visibility, b ambient accessibility,
// a edge cueing (contour lines, halos); the shading pass multiplies each into its term.
layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 3) uniform sampler2D u_shadow_dir;
layout(binding = 4) uniform sampler2D u_shadow_probe;
layout(binding = 5) uniform sampler2D u_ambient;
layout(binding = 6) uniform sampler2D u_edges;
layout(rgba16f, binding = 0) uniform writeonly image2D u_visibility;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_visibility)))) return;
    imageStore(u_visibility, px, vec4(texelFetch(u_shadow_dir, px, 0).r, texelFetch(u_shadow_probe, px, 0).r,
                                      texelFetch(u_ambient, px, 0).r, texelFetch(u_edges, px, 0).r));
}
