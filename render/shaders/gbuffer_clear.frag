#version 410 core
// The background's ids (an integer attachment cannot be cleared to -1 through the float
// clear colour, and moderngl has no integer clear): drawn into the ids attachment alone,
// the float attachments and the depth are cleared (render/passes/clear.py). With
// CUBE_WINDOW, into the whole G-buffer, the depth too, where the pixel's ray meets the
// navigation cube: the atoms' pixels cleared, the backbone trace's kept (cube_window.glsl).
#include "constants.glsl"
#ifdef CUBE_WINDOW
#include "camera.glsl"
#include "cube_window.glsl"
#include "gbuffer_out.glsl"
#else
layout(location = 0) out ivec2 o_ids;
#endif

void main() {
#ifdef CUBE_WINDOW
    if (!ray_meets_cube(u_eye, eye_ray(gl_FragCoord.xy))) discard;
    o_albedo = vec4(0.0);
    o_position = vec4(0.0);
    o_normal = vec4(0.0);
    gl_FragDepth = 1.0;
#endif
    o_ids = ivec2(ATOM_BACKGROUND, KIND_BACKGROUND);
}
