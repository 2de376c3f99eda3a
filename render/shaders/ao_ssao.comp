#version 430 core
// Screen-space ambient occlusion from the G-buffer, at full or half resolution
// (u_scale = 1 or 2 G-buffer pixels per output pixel), two ways:
//   point sampling (Crytek/hemisphere): points in the normal-oriented hemisphere of radius
//     R; a point counts as occluded when the visible surface at its pixel is in front of it
//     (by more than a small bias), faded out when that surface is far from the pixel's;
//   line sampling (Loos & Sloan's volumetric obscurance, as in Sculptor): screen-aligned
//     disk samples of the sphere of radius R around the point; each line through the
//     sphere along the view ray is occupied behind the visible surface, and the occupied
//     fraction of the sphere (0.5 on a flat surface) is rescaled so a flat surface is
//     unoccluded. Samples whose surface lies more than R in front are ignored.
// Both see only what the G-buffer shows: occluders off screen or hidden, and occluders
// farther than R, are missed. Output: 1 - intensity * occlusion, clamped to [0, 1].
layout(local_size_x = 8, local_size_y = 8) in;

#include "gbuffer_input.glsl"
#include "camera_input.glsl"
#include "sampling.glsl"

layout(r32f, binding = 0) uniform writeonly image2D u_accessibility;

uniform int u_scale;
uniform int u_samples;
uniform int u_line_sampling;
uniform float u_radius;     // Å
uniform float u_intensity;
uniform float u_bias;       // Å
uniform uint u_seed;

bool surface_depth_at(vec2 pixel, ivec2 size, out float depth) {
    ivec2 q = ivec2(floor(pixel));
    if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) return false;
    if (!gbuffer_lit(q)) return false;
    depth = view_depth(texelFetch(u_gb_position, q, 0).xyz);
    return true;
}

float point_sampling(vec3 p, vec3 n, float depth, ivec2 size, uint seed) {
    float occluded = 0.0;
    for (int i = 0; i < u_samples; ++i) {
        vec2 u = r2_sample(uint(i), seed);
        // more samples near the point: radius grows with the square of a stratified fraction
        float fraction = (float(i) + 0.5) / float(u_samples);
        vec3 s = p + cosine_direction(n, u) * u_radius * mix(0.1, 1.0, fraction * fraction);
        vec2 pixel;
        float surface;
        if (!project_to_pixel(s, vec2(size), pixel) || !surface_depth_at(pixel, size, surface)) continue;
        if (surface < view_depth(s) - u_bias) {
            occluded += smoothstep(0.0, 1.0, u_radius / abs(depth - surface));
        }
    }
    return occluded / float(u_samples);
}

// Occupied length of the line at `disk` (unit-disk offset): -1 when the depth buffer
// cannot tell (off screen, background, or a surface more than R in front).
float line_occupancy(vec2 disk, float half_length, float depth, ivec2 size, vec2 centre, float pixels_per_angstrom) {
    float surface;
    if (!surface_depth_at(centre + disk * u_radius * pixels_per_angstrom, size, surface)
        || surface < depth - half_length - u_radius) return -1.0;
    return clamp(depth + half_length - surface, 0.0, 2.0 * half_length);
}

float line_sampling(vec3 p, float depth, ivec2 size, uint seed, vec2 centre) {
    float pixels_per_angstrom = u_proj[1][1] * 0.5 * float(size.y) / depth;
    float occupied = 0.0, total = 0.0;
    // Samples come in pairs mirrored through the centre (as Loos & Sloan do), so any plane
    // gives exactly 0.5 and sampling noise cannot darken flat or convex surfaces; a pair
    // with a sample the depth buffer cannot tell about counts as flat.
    for (int i = 0; i < u_samples / 2; ++i) {
        vec2 u = r2_sample(uint(i), seed);
        vec2 disk = sqrt(u.x) * vec2(cos(6.283185307 * u.y), sin(6.283185307 * u.y));
        float half_length = u_radius * sqrt(max(0.0, 1.0 - dot(disk, disk)));
        float a = line_occupancy(disk, half_length, depth, size, centre, pixels_per_angstrom);
        float b = line_occupancy(-disk, half_length, depth, size, centre, pixels_per_angstrom);
        occupied += (a < 0.0 || b < 0.0) ? 2.0 * half_length : a + b;
        total += 4.0 * half_length;
    }
    float obscurance = total > 0.0 ? occupied / total : 0.5;
    return clamp(2.0 * obscurance - 1.0, 0.0, 1.0);
}

void main() {
    ivec2 out_px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(out_px, imageSize(u_accessibility)))) return;
    ivec2 size = textureSize(u_gb_ids, 0);
    ivec2 px = min(out_px * u_scale, size - 1);
    vec3 p, n;
    int atom;
    float ao = 1.0;
    if (gbuffer_fetch(px, p, n, atom)) {
        uint seed = pixel_seed(out_px, u_seed);
        float depth = view_depth(p);
        float occlusion = u_line_sampling != 0
            ? line_sampling(p, depth, size, seed, vec2(px) + 0.5)
            : point_sampling(p, n, depth, size, seed);
        ao = clamp(1.0 - u_intensity * occlusion, 0.0, 1.0);
    }
    imageStore(u_accessibility, out_px, vec4(ao));
}
