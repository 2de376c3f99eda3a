#version 410 core
uniform sampler2D u_text;  // RGBA, row 0 = top
uniform vec2 u_uv_scale;   // used part of the texture
in vec2 v_uv;
out vec4 o_color;

void main() {
    o_color = texture(u_text, v_uv * u_uv_scale);
}
