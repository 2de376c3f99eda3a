// Shadow rays of the directional light through its buffer (render/lighting/light_buffer.py
// DirectionalLightBuffer): the ray from o towards the light tests the atoms listed for the
// cell across the light holding o, nearest the light first, and stops at the first wholly
// behind o. The same occluders and the same minimum as trace_visibility (grid_traversal.glsl,
// included before this): the probe first (never clipped), then the kept atoms along the
// clipped ray. The cells' starts are bound at 19, past the occlusion atlas's bake buffers
// (which read it too); the entries are tables in images 6 and 7 (table_image.glsl), past the
// images of the passes that include this.
#include "table_image.glsl"
layout(std430, binding = 19) readonly buffer SunCellStart { uint sun_start[]; };  // CSR offsets per cell
layout(rgba32f, binding = 6) readonly uniform image2D u_sun_spheres;  // centre, vdW radius
layout(r32i, binding = 7) readonly uniform iimage2D u_sun_atoms;

uniform vec3 u_sb_u;         // the axes across the light
uniform vec3 u_sb_v;
uniform vec2 u_sb_origin;    // Å along u and v: the corner of cell (0, 0)
uniform float u_sb_cell;     // Å
uniform ivec2 u_sb_dims;
uniform float u_sb_behind;   // Å: the largest listed reach (vdW + shell + margin); a centre
                             // farther than this behind o cannot darken its ray

float trace_sun_visibility(vec3 o, vec3 d, int skip_atom, vec2 shell, float growth, bool with_probe) {
    float vis = 1.0;
    if (with_probe && u_probe_sphere.w > 0.0) {  // the probe is never clipped
        vis = occluder_visibility(o, d, 0.0, BIG, u_probe_sphere, shell, growth);
        if (vis <= 0.0) return 0.0;
    }
    float t0 = 0.0, t1 = BIG;
    vec3 cut_normal;
    if (!clip_ray(o, d, t0, t1, cut_normal)) return vis;
    ivec2 cell = ivec2(floor((vec2(dot(o, u_sb_u), dot(o, u_sb_v)) - u_sb_origin) / u_sb_cell));
    if (any(lessThan(cell, ivec2(0))) || any(greaterThanEqual(cell, u_sb_dims))) return vis;
    uint id = uint(cell.x + u_sb_dims.x * cell.y);
    float behind = dot(o, d) - u_sb_behind;
    for (uint k = sun_start[id]; k < sun_start[id + 1u]; ++k) {
        vec4 sphere = imageLoad(u_sun_spheres, table_texel(k));
        if (dot(sphere.xyz, d) < behind) break;  // this one and every later one
        if (imageLoad(u_sun_atoms, table_texel(k)).x == skip_atom) continue;
        vis = min(vis, occluder_visibility(o, d, t0, t1, sphere, shell, growth));
        if (vis <= 0.0) return 0.0;
    }
    return vis;
}
