#version 430 core
// The occlusion atlas looked up per G-buffer pixel (render/lighting/ao/precomputed.py): a
// sphere pixel reads its atom's patch in the direction from the atom's centre, bilinearly.
// A cap lies on the boundary of the kept region (clip planes and cube make it convex), so
// every ray leaving it outwards leaves that region for good and nothing drawn can stop it:
// its accessibility is 1 and it sees the light when it faces it. With a probe in the grid
// (whole frames), the probe's analytic share of the occlusion and its shadow of the light
// are taken in as visibility_compose.comp does on layered frames.
layout(local_size_x = 8, local_size_y = 8) in;

#include "grid_traversal.glsl"
#include "gbuffer_input.glsl"
#include "lights.glsl"
#include "ao_sphere.glsl"
#include "atlas_common.glsl"

layout(std430, binding = 4) readonly buffer AtomSlots { int atom_slots[]; };  // patch of each atom, -1 none
layout(binding = 3) uniform sampler2D u_atlas;
layout(r32f, binding = 0) uniform writeonly image2D u_ambient;
layout(r32f, binding = 1) uniform writeonly image2D u_sun;

uniform vec2 u_atlas_size;
uniform int u_write_sun;  // 0: the light channel is not wanted (u_sun keeps what it holds)

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_ambient)))) return;
    vec3 p, n;
    int atom;
    float ambient = 1.0, sun = 1.0;
    if (gbuffer_fetch(px, p, n, atom) && atom >= 0) {
        int kind = texelFetch(u_gb_ids, px, 0).g;
        int slot = atom_slots[atom];
        if (kind == KIND_CAP) {
            sun = dot(n, u_sun_dir) > 0.0 ? 1.0 : 0.0;
        } else if (slot >= 0) {
            vec2 baked = textureLod(u_atlas, atlas_coord(slot, normalize(p - spheres[atom].xyz)) / u_atlas_size, 0.0).rg;
            ambient = baked.r;
            sun = baked.g;
        } else {
            ambient = sun = 0.0;
        }
        if (u_probe_sphere.w > 0.0) {
            ambient *= 1.0 - sphere_occlusion(p, n, u_probe_sphere);
            if (sun > 0.0) sun = min(sun, occluder_visibility(ray_origin(p, n), u_sun_dir, 0.0, BIG, u_probe_sphere,
                                                              vec2(0.0), 0.0));
        }
    }
    imageStore(u_ambient, px, vec4(ambient));
    if (u_write_sun != 0) imageStore(u_sun, px, vec4(sun));
}
