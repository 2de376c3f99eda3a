#version 430 core
// Progressive path tracing from the G-buffer's primary hits (Easdon 2013, Algorithm 2):
// at every vertex both lights are sampled directly with a shadow ray through the grid
// (they are delta lights, so this is their whole contribution); the path then continues
// in a cosine-weighted direction (throughput *= albedo for the Lambertian lobe) up to
// u_bounces times, and a ray that escapes the molecule gathers the sky's radiance.
// Materials are per element (render/lighting/materials.py): albedo and a normalised Phong lobe
// that only the lights' direct highlights use. Output: linear radiance, running mean.
layout(local_size_x = 8, local_size_y = 8) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "sampling.glsl"
#include "lights.glsl"

struct Material { vec4 albedo_specular; vec4 exponent; };
layout(std430, binding = 5) readonly buffer Materials { Material materials[]; };
layout(rgba32f, binding = 0) uniform image2D u_radiance;

uniform uint u_first_sample;
uniform int u_spp;
uniform uint u_seed;
uniform int u_bounces;
uniform vec3 u_eye;
uniform vec3 u_sky;
uniform vec3 u_background;
uniform vec4 u_probe_albedo_specular;
uniform float u_probe_exponent;

const float INV_PI = 0.3183098861837907;

void material_of(int atom, out vec3 albedo, out float specular, out float exponent) {
    if (atom == ATOM_PROBE) {
        albedo = u_probe_albedo_specular.rgb;
        specular = u_probe_albedo_specular.a;
        exponent = u_probe_exponent;
    } else {
        albedo = materials[atom].albedo_specular.rgb;
        specular = materials[atom].albedo_specular.a;
        exponent = materials[atom].exponent.x;
    }
}

vec3 brdf(vec3 albedo, float specular, float exponent, vec3 n, vec3 l, vec3 v) {
    vec3 r = reflect(-l, n);
    float lobe = specular * (exponent + 2.0) * 0.5 * INV_PI * pow(max(dot(r, v), 0.0), exponent);
    return albedo * INV_PI + vec3(lobe);
}

vec3 direct_light(vec3 p, vec3 n, vec3 v, int atom, vec3 albedo, float specular, float exponent) {
    vec3 o = ray_origin(p, n);
    vec3 sum = vec3(0.0);
    float c = dot(n, u_sun_dir);
    if (u_sun_intensity > 0.0 && c > 0.0) {
        float vis = trace_visibility(o, u_sun_dir, 0.0, BIG, atom, vec2(0.0), 0.0, atom != ATOM_PROBE);
        sum += brdf(albedo, specular, exponent, n, u_sun_dir, v) * u_sun_intensity * c * vis;
    }
    if (u_probe_light_on != 0 && atom != ATOM_PROBE && distance(p, u_probe_light_pos) <= u_probe_light_radius) {
        vec3 to_light = u_probe_light_pos - o;
        float d = length(to_light);
        vec3 l = to_light / d;
        c = dot(n, l);
        if (c > 0.0) {
            float vis = trace_visibility(o, l, 0.0, d, atom, vec2(0.0), 0.0, false);
            sum += brdf(albedo, specular, exponent, n, l, v) * u_probe_light_intensity
                   * probe_light_falloff(distance(p, u_probe_light_pos)) * c * vis;
        }
    }
    return sum;
}

// The first bounce follows the pixel's R2 sequence; deeper ones, whose dimensions R2 would
// correlate with the first, use hashed random numbers.
vec2 bounce_sample(uint i, uint seed, int bounce) {
    if (bounce == 0) return r2_sample(i, seed);
    uint h = pcg_hash(seed ^ pcg_hash(i * 8u + uint(bounce)));
    return vec2(h >> 8u, pcg_hash(h) >> 8u) * (1.0 / 16777216.0);
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_radiance)))) return;
    vec3 p0, n0;
    int atom0;
    if (!gbuffer_fetch(px, p0, n0, atom0)) {
        imageStore(u_radiance, px, vec4(u_background, 1.0));
        return;
    }
    uint seed = pixel_seed(px, u_seed);
    vec3 total = vec3(0.0);
    for (int s = 0; s < u_spp; ++s) {
        uint index = u_first_sample + uint(s);
        vec3 p = p0, n = n0, v = normalize(u_eye - p0);
        int atom = atom0;
        vec3 throughput = vec3(1.0);
        for (int bounce = 0; ; ++bounce) {
            vec3 albedo;
            float specular, exponent;
            material_of(atom, albedo, specular, exponent);
            total += throughput * direct_light(p, n, v, atom, albedo, specular, exponent);
            if (bounce >= u_bounces) break;
            vec3 o = ray_origin(p, n);
            vec3 d = cosine_direction(n, bounce_sample(index, seed, bounce));
            throughput *= albedo;
            float t;
            int hit;
            vec3 hit_normal;
            bool cap;
            if (!trace_closest(o, d, 0.0, BIG, atom, true, t, hit, hit_normal, cap)) {
                total += throughput * u_sky;
                break;
            }
            p = o + t * d;
            n = hit_normal;
            v = -d;
            atom = hit;
        }
    }
    vec3 before = u_first_sample > 0u ? imageLoad(u_radiance, px).rgb * float(u_first_sample) : vec3(0.0);
    imageStore(u_radiance, px, vec4((before + total) / float(u_first_sample + uint(u_spp)), 1.0));
}
