#version 410 core
// Copies the G-buffer's four layers and its depth from one set of textures to another,
// pixel for pixel (drawn with a scissor box: the rectangle the probe covers).
#include "gbuffer_out.glsl"

uniform sampler2D u_src_albedo;
uniform sampler2D u_src_position;
uniform sampler2D u_src_normal;
uniform isampler2D u_src_ids;
uniform sampler2D u_src_depth;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    o_albedo = texelFetch(u_src_albedo, px, 0);
    o_position = texelFetch(u_src_position, px, 0);
    o_normal = texelFetch(u_src_normal, px, 0);
    o_ids = texelFetch(u_src_ids, px, 0).xy;
    gl_FragDepth = texelFetch(u_src_depth, px, 0).r;
}
