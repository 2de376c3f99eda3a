#version 410 core
// A screen-aligned textured rectangle (the text readout), placed in pixels.
uniform vec4 u_rect;      // x, y (top-left, pixels from the top-left corner), width, height
uniform vec2 u_screen;    // target size in pixels
out vec2 v_uv;

void main() {
    vec2 corner = vec2(gl_VertexID & 1, (gl_VertexID >> 1) & 1);
    vec2 px = u_rect.xy + corner * u_rect.zw;
    v_uv = corner;
    gl_Position = vec4(px.x / u_screen.x * 2.0 - 1.0, 1.0 - px.y / u_screen.y * 2.0, 0.0, 1.0);
}
