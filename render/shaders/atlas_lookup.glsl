// The occlusion atlas looked up per G-buffer pixel (render/lighting/ao/precomputed.py): a
// sphere pixel reads its atom's patch in the direction from the atom's centre, bilinearly.
// A cap lies on the boundary of the kept region (clip planes and cube make it convex), so
// every ray leaving it outwards leaves that region for good and nothing drawn can stop it:
// its accessibility is 1 and it sees a light when it faces it. Pixels beyond the probe
// light's range see it (1: unlit anyway, as shadows.comp writes them). With a probe in the
// grid (whole frames), the probe's analytic share of the occlusion and its shadow of the
// directional light are taken in, as on layered frames visibility_terms.glsl takes in its
// shadow and the shading pass its share (probe_share.glsl). Compiled per case: WITH_PROBE
// (a probe in the grid), and WRITE_AMBIENT / WRITE_SUN / WRITE_PROBE for the terms wanted
// (the others keep what they hold).
// look_up is run by atlas_lookup.comp over a rectangle, and by atlas_lookup.frag on the
// pixels a depth test picks.

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "lights.glsl"
#include "ao_sphere.glsl"
#include "atlas_common.glsl"

layout(std430, binding = 4) readonly buffer AtomSlots { int atom_slots[]; };  // patch of each atom, -1 none
layout(binding = 3) uniform sampler2D u_atlas;
layout(r32f, binding = 0) uniform writeonly image2D u_ambient;
layout(r32f, binding = 1) uniform writeonly image2D u_sun;
layout(r32f, binding = 2) uniform writeonly image2D u_probe_light;

uniform vec2 u_atlas_size;

// The terms wanted, written (the others keep what they hold).
void store_terms(ivec2 px, float ambient, float sun, float lamp) {
#ifdef WRITE_AMBIENT
    imageStore(u_ambient, px, vec4(ambient));
#endif
#ifdef WRITE_SUN
    imageStore(u_sun, px, vec4(sun));
#endif
#ifdef WRITE_PROBE
    imageStore(u_probe_light, px, vec4(lamp));
#endif
}

void look_up(ivec2 px) {
    vec3 p, n;
    int atom, kind;
    float ambient = 1.0, sun = 1.0, lamp = 1.0;
    if (gbuffer_fetch(px, p, n, atom, kind) && atom >= 0) {
        int slot = atom_slots[atom];
        if (kind == KIND_CAP) {
            sun = dot(n, u_sun_dir) > 0.0 ? 1.0 : 0.0;
            lamp = dot(n, u_probe_light_pos - p) > 0.0 ? 1.0 : 0.0;
        } else if (slot >= 0) {
            vec3 baked = textureLod(u_atlas, atlas_coord(slot, normalize(p - grid_sphere(atom).xyz)) / u_atlas_size, 0.0).rgb;
            ambient = baked.r;
            sun = baked.g;
            lamp = baked.b;
        } else {
            ambient = sun = lamp = 0.0;
        }
        if (distance(p, u_probe_light_pos) > u_probe_light_radius) lamp = 1.0;
#ifdef WITH_PROBE
        ambient *= 1.0 - probe_occlusion(p, n, u_probe_sphere, u_probe_reach);
        if (sun > 0.0) sun = min(sun, occluder_visibility(ray_origin(p, n), u_sun_dir, 0.0, BIG, u_probe_sphere,
                                                          vec2(0.0), 0.0));
#endif
    }
    store_terms(px, ambient, sun, lamp);
}
