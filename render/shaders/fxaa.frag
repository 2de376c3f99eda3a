#version 410 core
// FXAA after T. Lottes (the low-cost "console" variant): where the local luma contrast
// is high, blur along the edge direction estimated from the four diagonal neighbours,
// with two taps (A) or four (B), keeping B unless it leaves the neighbourhood's range.
// No search loop, nine fetches at most: cheap on software rasterisers too.
uniform sampler2D u_color;
uniform vec2 u_texel;  // 1 / size
out vec4 o_color;

#define EDGE_THRESHOLD 0.125
#define EDGE_THRESHOLD_MIN 0.0312
#define REDUCE_MIN (1.0 / 128.0)
#define REDUCE_MUL (1.0 / 8.0)
#define SPAN_MAX 8.0

const vec3 LUMA = vec3(0.299, 0.587, 0.114);

float luma_at(ivec2 px, ivec2 offset) {
    ivec2 size = textureSize(u_color, 0);
    return dot(texelFetch(u_color, clamp(px + offset, ivec2(0), size - 1), 0).rgb, LUMA);
}

vec3 rgb(vec2 uv) { return textureLod(u_color, uv, 0.0).rgb; }

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec2 uv = gl_FragCoord.xy * u_texel;
    vec3 center = texelFetch(u_color, px, 0).rgb;
    float m = dot(center, LUMA);
    float nw = luma_at(px, ivec2(-1, 1)), ne = luma_at(px, ivec2(1, 1));
    float sw = luma_at(px, ivec2(-1, -1)), se = luma_at(px, ivec2(1, -1));
    float lo = min(m, min(min(nw, ne), min(sw, se)));
    float hi = max(m, max(max(nw, ne), max(sw, se)));
    if (hi - lo < max(EDGE_THRESHOLD_MIN, hi * EDGE_THRESHOLD)) {
        o_color = vec4(center, 1.0);
        return;
    }
    vec2 dir = vec2(-((nw + ne) - (sw + se)), (nw + sw) - (ne + se));
    float reduce = max((nw + ne + sw + se) * 0.25 * REDUCE_MUL, REDUCE_MIN);
    float scale = 1.0 / (min(abs(dir.x), abs(dir.y)) + reduce);
    dir = clamp(dir * scale, vec2(-SPAN_MAX), vec2(SPAN_MAX)) * u_texel;
    vec3 a = 0.5 * (rgb(uv + dir * (1.0 / 3.0 - 0.5)) + rgb(uv + dir * (2.0 / 3.0 - 0.5)));
    vec3 b = a * 0.5 + 0.25 * (rgb(uv - dir * 0.5) + rgb(uv + dir * 0.5));
    float lb = dot(b, LUMA);
    o_color = vec4((lb < lo || lb > hi) ? a : b, 1.0);
}
