#version 410 core
// Ray-cast sphere impostor: exact ray-sphere hit per pixel, cut by the clipping planes
// into a solid (the entry point moves onto the plane that removes it: a cap carrying
// the plane's outward normal), written to the G-buffer with its true depth.
#ifdef GL_ARB_conservative_depth
#extension GL_ARB_conservative_depth : enable
layout(depth_greater) out float gl_FragDepth;
#endif

#include "camera.glsl"
#include "clip.glsl"
#include "gbuffer_out.glsl"

in VertexData {
    flat vec4 sphere;
    flat vec3 color;
    flat int id;
} fs_in;

uniform int u_probe;  // 1: this draw is the probe (own id and kind)

void main() {
    vec3 d = eye_ray(gl_FragCoord.xy);
    vec3 c = fs_in.sphere.xyz;
    float r = fs_in.sphere.w;
    // Stable form (Haines et al., Ray Tracing Gems ch. 7): no b^2 - c cancellation.
    vec3 oc = c - u_eye;
    float b = dot(oc, d);
    vec3 off = oc - b * d;
    float h = r * r - dot(off, off);
    if (h < 0.0) discard;
    h = sqrt(h);
    float t0 = b - h, t1 = b + h;
    int plane;
    if (!clip_interval(u_eye, d, t0, t1, plane)) discard;
    vec3 p = u_eye + t0 * d;
    bool cap = plane >= 0;
    vec3 n = cap ? -u_planes[plane].xyz : (p - c) / r;
    int kind = u_probe == 1 ? KIND_PROBE : (cap ? KIND_CAP : KIND_SPHERE);
    write_gbuffer(fs_in.color, p, n, u_probe == 1 ? ATOM_PROBE : fs_in.id, kind);
    gl_FragDepth = window_depth(p);
}
