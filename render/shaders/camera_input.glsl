// The camera of the frame the G-buffer was drawn with (OpenGL conventions).
const float BIG_DEPTH = 1e30;  // the view depth of background pixels
uniform mat4 u_view;
uniform mat4 u_proj;

float view_depth(vec3 world) { return -(u_view * vec4(world, 1.0)).z; }

// Fractional G-buffer pixel coordinates of a world point; false behind the camera.
bool project_to_pixel(vec3 world, vec2 size, out vec2 pixel) {
    vec4 clip = u_proj * (u_view * vec4(world, 1.0));
    if (clip.w <= 0.0) return false;
    pixel = (clip.xy / clip.w * 0.5 + 0.5) * size;
    return true;
}
