// Deferred shading pass: Phong with a directional light and the probe's point light
// (attenuated with distance), CPK albedo, the touched atom highlighted, the probe glowing.
// Every light term is multiplied by its own visibility factor, read from u_visibility:
//   r: directional-light visibility (shadow), b: ambient accessibility (ambient occlusion,
//   raised to u_ao_power); and the whole colour, background included, by a: edge cueing
//   (contour lines, halos). The targets clear it to 1.0; lighting passes that run before
//   this one fill it. Compiled with PROBE_SHADOWED, the probe light's visibility comes
//   from u_probe_visibility (the lighting traced it or took it from the occlusion atlas);
//   with TRACE_PROBE_LIGHT (shading_traced.frag, GL 4.3) it is traced here, per pixel, through
//   the light buffer the lighting built (light_visibility.glsl): a pass of its own would
//   fetch the same G-buffer texels again, which costs llvmpipe more than the trace's
//   arithmetic; with PROBE_SHARE (layered frames) the probe's shadow of the sun and its
//   share of the ambient occlusion are taken in here (probe_share.glsl). Each is its own
//   program: llvmpipe runs every instruction of a shader, branches taken or not.
// The probe light reaches u_probe_range Å: its attenuation is windowed to 0 there. It lights
// the atoms, not the backbone trace (context, lit by the directional and ambient light only).
// BACKGROUND_ONLY: the program for background pixels (the pass picks them by depth).
// CONTEXT: the program for the backbone trace, where no atom and no probe lie: no probe light.
#include "constants.glsl"
// occluders.glsl and ray_origin.glsl here, not only through the cases' files below: an
// include is expanded once, where it first appears, whether its #ifdef holds or not.
#include "occluders.glsl"
#include "ray_origin.glsl"
#include "light_terms.glsl"
#ifdef PROBE_SHARE
#include "probe_share.glsl"
#endif
#ifdef TRACE_PROBE_LIGHT
#include "light_visibility.glsl"
#endif

uniform sampler2D u_albedo;
uniform sampler2D u_position;
uniform sampler2D u_normal;
uniform isampler2D u_ids;
uniform sampler2D u_visibility;
#ifdef PROBE_SHADOWED
uniform sampler2D u_probe_visibility;
#endif

uniform vec3 u_eye;
uniform vec3 u_background;
uniform float u_ambient;
uniform float u_ao_power;        // accessibility ** power: > 1 strengthens the occlusion
uniform int u_dir_enabled;
uniform vec3 u_light_dir;        // direction the light travels (unit, world)
uniform float u_dir_intensity;
uniform int u_probe_light_enabled;
uniform vec3 u_probe_center;
uniform float u_probe_intensity;
uniform int u_touched_atom;      // -1: none
uniform vec3 u_highlight;        // touched-atom colour
uniform vec3 u_probe_color;

#ifdef GBUFFER_IMAGES  // the layers read as images: llvmpipe loads those cheaper than a texelFetch
layout(rgba32f, binding = 0) readonly uniform image2D u_position_image;
layout(rgba32f, binding = 1) readonly uniform image2D u_normal_image;
layout(rgba32f, binding = 6) readonly uniform image2D u_visibility_image;
layout(rg32i, binding = 7) readonly uniform iimage2D u_ids_image;
#define LOAD(layer, px) imageLoad(layer##_image, px)
#else
#define LOAD(layer, px) texelFetch(layer, px, 0)
#endif

out vec4 o_color;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
#ifdef BACKGROUND_ONLY
    o_color = vec4(u_background * LOAD(u_visibility, px).a, 1.0);
#else
    ivec2 ids = LOAD(u_ids, px).xy;
    vec3 p = LOAD(u_position, px).xyz;
    vec3 n = normalize(LOAD(u_normal, px).xyz);
#if defined(TRACE_PROBE_LIGHT) && !defined(CONTEXT)  // as shadow_pixel.glsl has it: spheres and caps are traced
    // before the other layers are fetched, so that fewer values live through its loop
    float probe_shadow = light_visibility(ids.y == KIND_SPHERE || ids.y == KIND_CAP, p, n, ids.x);
#endif
    vec4 vis = LOAD(u_visibility, px);
    vec3 albedo = texelFetch(u_albedo, px, 0).rgb;
    vec3 v = normalize(u_eye - p);
    if (ids.y == KIND_PROBE) {  // the light source itself: bright, lightly shaded
        o_color = vec4(u_probe_color * (0.75 + 0.25 * max(dot(n, v), 0.0)) * vis.a, 1.0);
        return;
    }
    if (u_touched_atom >= 0 && ids.x == u_touched_atom && ids.y != KIND_BACKBONE)
        albedo = mix(albedo, u_highlight, 0.6);
    float sun = vis.r, ambient = vis.b;
#if defined(PROBE_SHARE) && !defined(CONTEXT)
    if ((ids.y == KIND_SPHERE || ids.y == KIND_CAP) && ids.x >= 0) add_probe_share(p, n, sun, ambient);
#endif
    vec3 color = u_ambient * pow(ambient, u_ao_power) * albedo;
    if (u_dir_enabled == 1)
        color += sun * u_dir_intensity * phong(albedo, n, v, -u_light_dir);
#ifndef CONTEXT
    if (u_probe_light_enabled == 1 && ids.y != KIND_BACKBONE) {  // the trace is context: not the probe's to light
        vec3 to_probe = u_probe_center - p;
        float dist = length(to_probe);
        float atten = probe_attenuation(dist);
#if defined(PROBE_SHADOWED)
        float shadow = texelFetch(u_probe_visibility, px, 0).r;
#elif defined(TRACE_PROBE_LIGHT)
        float shadow = probe_shadow;
#else
        float shadow = 1.0;
#endif
        color += shadow * u_probe_intensity * atten * phong(albedo, n, v, to_probe / max(dist, 1e-6));
    }
#endif
    o_color = vec4(min(color, vec3(1.0)) * vis.a, 1.0);
#endif
}
