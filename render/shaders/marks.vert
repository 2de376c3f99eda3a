#version 410 core
// One numbered badge per mark, centred on the mark's projection, a fixed size in pixels.
// A mark hidden behind atoms is drawn faded: the G-buffer's visible point at its pixel is
// nearer the eye than the mark by more than u_tolerance (the probe around a fresh mark is
// not "in front" of it).
in vec4 in_mark;             // position xyz (Å), atlas cell
uniform mat4 u_viewproj;
uniform vec3 u_eye;
uniform vec2 u_screen;       // target size, pixels
uniform float u_badge_px;
uniform vec2 u_cells;        // atlas columns, rows
uniform float u_tolerance;   // Å
uniform sampler2D u_position;  // G-buffer world positions (w = 1 where covered)
out vec2 v_uv;
out float v_alpha;

void main() {
    vec2 corner = vec2(gl_VertexID & 1, (gl_VertexID >> 1) & 1);
    vec4 clip = u_viewproj * vec4(in_mark.xyz, 1.0);
    v_uv = vec2(0.0);
    v_alpha = 0.0;
    if (clip.w <= 0.0) {  // behind the camera: outside the clip volume
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
        return;
    }
    vec2 anchor = (clip.xy / clip.w * 0.5 + 0.5) * u_screen;  // pixels from the bottom left
    ivec2 texel = ivec2(clamp(anchor, vec2(0.0), u_screen - 1.0));
    vec4 hit = texelFetch(u_position, texel, 0);
    bool hidden = hit.w > 0.0 && distance(hit.xyz, u_eye) < distance(in_mark.xyz, u_eye) - u_tolerance;
    v_alpha = hidden ? 0.45 : 1.0;
    vec2 px = anchor + (corner - 0.5) * u_badge_px;
    gl_Position = vec4(px / u_screen * 2.0 - 1.0, 0.0, 1.0);
    vec2 cell = vec2(mod(in_mark.w, u_cells.x), floor(in_mark.w / u_cells.x));
    v_uv = (cell + vec2(corner.x, 1.0 - corner.y)) / u_cells;  // atlas row 0 is its top
}
