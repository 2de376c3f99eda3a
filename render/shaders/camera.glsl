// Camera uniforms shared by every pass that casts rays or projects points (world frame, Å).
uniform mat4 u_viewproj;    // projection * view (column vectors)
uniform vec3 u_eye;         // camera position
uniform mat3 u_cam_basis;   // columns: camera right, up, backward (the inverse view rotation)
uniform vec4 u_ray_scale;   // 1/P[0][0], 1/P[1][1], P[2][0], P[2][1] of the projection
uniform vec4 u_viewport;    // x, y, width, height of the target in pixels

// Unit world-space direction of the eye ray through a window position (pixel centre
// = gl_FragCoord.xy), the same ray the CPU reference casts.
vec3 eye_ray(vec2 frag_xy) {
    vec2 ndc = (frag_xy - u_viewport.xy) / u_viewport.zw * 2.0 - 1.0;
    vec3 view_dir = vec3((ndc.x + u_ray_scale.z) * u_ray_scale.x, (ndc.y + u_ray_scale.w) * u_ray_scale.y, -1.0);
    return normalize(u_cam_basis * view_dir);
}

// Window depth (default depth range [0, 1]) of a world point.
float window_depth(vec3 p) {
    vec4 clip = u_viewproj * vec4(p, 1.0);
    return clamp(clip.z / clip.w * 0.5 + 0.5, 0.0, 1.0);
}
