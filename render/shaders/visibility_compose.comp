#version 430 core
// The renderer's visibility buffer (render/gl/targets.py, RGBA16F) from the lighting terms:
// r directional-light visibility, g probe-light visibility, b ambient accessibility,
// a edge cueing (contour lines, halos); the shading pass multiplies each into its term.
//
// Layered frames (u_layered, the frame cache: render/passes/lighting.py) bring the
// molecule's own terms, computed without the probe, and add what the probe changes here:
//   the sun: min(molecule's visibility, the probe sphere's along the same ray) on atom
//     pixels (exactly trace_visibility's minimum over the occluders); the probe's own
//     pixels bring theirs traced (u_probe_pixels_sun);
//   ambient: the molecule's times the probe's analytic share, 1 - occlusion of one sphere
//     (as ao_analytic.comp multiplies it in), on atom pixels; the probe's pixels get the
//     analytic occlusion of the atoms nearest the probe.
// With u_write_terms it also writes the composed sun and ambient terms (r32f), for the
// G-buffer export only (run again then: each image written costs llvmpipe as much as the rest).
layout(local_size_x = 8, local_size_y = 8) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "lights.glsl"
#include "ao_sphere.glsl"

#define MAX_K 32
layout(binding = 3) uniform sampler2D u_shadow_dir;
layout(binding = 4) uniform sampler2D u_shadow_probe;
layout(binding = 5) uniform sampler2D u_ambient;
layout(binding = 6) uniform sampler2D u_edges;
layout(binding = 7) uniform sampler2D u_probe_pixels_sun;
layout(rgba16f, binding = 0) uniform writeonly image2D u_visibility;
layout(r32f, binding = 1) uniform writeonly image2D u_sun_out;
layout(r32f, binding = 2) uniform writeonly image2D u_ambient_out;

uniform int u_layered;
uniform int u_write_terms;
uniform int u_probe_sun;        // the probe shadows the sun's light on the molecule
uniform int u_probe_ambient;    // the probe's share of the ambient occlusion
uniform vec2 u_shell;           // the sun's soft-shadow shell (shadows.comp)
uniform float u_shell_growth;
uniform int u_k;
uniform int u_probe_neighbours[MAX_K];

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_visibility)))) return;
    float sun = texelFetch(u_shadow_dir, px, 0).r;
    float ambient = texelFetch(u_ambient, px, 0).r;
    if (u_layered != 0) {
        vec3 p, n;
        int atom;
        if (gbuffer_fetch(px, p, n, atom)) {
            if (atom == ATOM_PROBE) {
                if (u_probe_sun != 0) sun = texelFetch(u_probe_pixels_sun, px, 0).r;
                if (u_probe_ambient != 0) {
                    ambient = 1.0;
                    for (int j = 0; j < u_k; ++j) ambient *= neighbour_accessibility(p, n, u_probe_neighbours[j]);
                }
            } else if (atom >= 0) {
                if (u_probe_sun != 0 && sun > 0.0)
                    sun = min(sun, occluder_visibility(ray_origin(p, n), u_sun_dir, 0.0, BIG, u_probe_sphere,
                                                       u_shell, u_shell_growth));
                if (u_probe_ambient != 0) ambient *= 1.0 - sphere_occlusion(p, n, u_probe_sphere);
            }
        }
        if (u_write_terms != 0) {
            imageStore(u_sun_out, px, vec4(sun));
            imageStore(u_ambient_out, px, vec4(ambient));
        }
    }
    imageStore(u_visibility, px, vec4(sun, texelFetch(u_shadow_probe, px, 0).r, ambient,
                                      texelFetch(u_edges, px, 0).r));
}
