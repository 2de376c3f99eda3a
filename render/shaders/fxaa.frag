#version 410 core
// FXAA (after T. Lottes, FXAA 3.11 "quality" edge walk, reduced): finds luma edges,
// walks along them to estimate the sub-pixel edge position and blends across it.
uniform sampler2D u_color;
uniform vec2 u_texel;  // 1 / size
out vec4 o_color;

#define EDGE_THRESHOLD 0.125
#define EDGE_THRESHOLD_MIN 0.0312
#define SUBPIXEL 0.75
#define STEPS 10

float luma(vec2 uv) { return dot(textureLod(u_color, uv, 0.0).rgb, vec3(0.299, 0.587, 0.114)); }

void main() {
    vec2 uv = gl_FragCoord.xy * u_texel;
    vec3 center_rgb = textureLod(u_color, uv, 0.0).rgb;
    float m = dot(center_rgb, vec3(0.299, 0.587, 0.114));
    float n = luma(uv + vec2(0.0, u_texel.y)), s = luma(uv - vec2(0.0, u_texel.y));
    float e = luma(uv + vec2(u_texel.x, 0.0)), w = luma(uv - vec2(u_texel.x, 0.0));
    float lo = min(m, min(min(n, s), min(e, w)));
    float hi = max(m, max(max(n, s), max(e, w)));
    float range = hi - lo;
    if (range < max(EDGE_THRESHOLD_MIN, hi * EDGE_THRESHOLD)) {
        o_color = vec4(center_rgb, 1.0);
        return;
    }
    float ne = luma(uv + u_texel), sw = luma(uv - u_texel);
    float nw = luma(uv + vec2(-u_texel.x, u_texel.y)), se = luma(uv + vec2(u_texel.x, -u_texel.y));
    // Sub-pixel aliasing amount from the 3x3 neighbourhood.
    float average = (2.0 * (n + s + e + w) + ne + nw + se + sw) / 12.0;
    float sub = clamp(abs(average - m) / range, 0.0, 1.0);
    sub = smoothstep(0.0, 1.0, sub);
    float sub_blend = sub * sub * SUBPIXEL;
    // Edge orientation.
    float horizontal = abs(n + s - 2.0 * m) * 2.0 + abs(ne + se - 2.0 * e) + abs(nw + sw - 2.0 * w);
    float vertical = abs(e + w - 2.0 * m) * 2.0 + abs(ne + nw - 2.0 * n) + abs(se + sw - 2.0 * s);
    bool is_h = horizontal >= vertical;
    float step_len = is_h ? u_texel.y : u_texel.x;
    float l_pos = is_h ? n : e, l_neg = is_h ? s : w;
    float g_pos = abs(l_pos - m), g_neg = abs(l_neg - m);
    bool pos_side = g_pos >= g_neg;
    float gradient = max(g_pos, g_neg);
    float edge_luma = 0.5 * (m + (pos_side ? l_pos : l_neg));
    if (!pos_side) step_len = -step_len;
    vec2 edge_uv = uv + (is_h ? vec2(0.0, 0.5 * step_len) : vec2(0.5 * step_len, 0.0));
    vec2 along = is_h ? vec2(u_texel.x, 0.0) : vec2(0.0, u_texel.y);
    // Walk both ways along the edge until the luma leaves the edge's value.
    float scale = gradient * 0.25;
    vec2 up = edge_uv + along, dn = edge_uv - along;
    float d_up = luma(up) - edge_luma, d_dn = luma(dn) - edge_luma;
    bool done_up = abs(d_up) >= scale, done_dn = abs(d_dn) >= scale;
    for (int i = 0; i < STEPS && !(done_up && done_dn); ++i) {
        float stride = i < 4 ? 1.0 : 2.0;
        if (!done_up) { up += along * stride; d_up = luma(up) - edge_luma; done_up = abs(d_up) >= scale; }
        if (!done_dn) { dn -= along * stride; d_dn = luma(dn) - edge_luma; done_dn = abs(d_dn) >= scale; }
    }
    float dist_up = is_h ? up.x - uv.x : up.y - uv.y;
    float dist_dn = is_h ? uv.x - dn.x : uv.y - dn.y;
    bool up_nearer = dist_up < dist_dn;
    float dist = min(dist_up, dist_dn);
    float span = dist_up + dist_dn;
    bool m_smaller = m - edge_luma < 0.0;
    bool correct = ((up_nearer ? d_up : d_dn) < 0.0) != m_smaller;
    float edge_blend = correct ? 0.5 - dist / span : 0.0;
    float blend = max(edge_blend, sub_blend);
    vec2 final_uv = uv + (is_h ? vec2(0.0, blend * step_len) : vec2(blend * step_len, 0.0));
    o_color = vec4(textureLod(u_color, final_uv, 0.0).rgb, 1.0);
}
