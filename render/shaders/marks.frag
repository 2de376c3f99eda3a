#version 410 core
uniform sampler2D u_atlas;  // RGBA badges, row 0 = top
in vec2 v_uv;
in float v_alpha;
out vec4 o_color;

void main() {
    vec4 c = texture(u_atlas, v_uv);
    if (c.a * v_alpha <= 0.0) {
        discard;
    }
    o_color = vec4(c.rgb, c.a * v_alpha);
}
