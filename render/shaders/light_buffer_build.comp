#version 430 core
// The probe light's light buffer (render/lighting/light_buffer.py): one invocation per
// cube cell lists, nearest first, the atoms in reach whose cone of directions seen from
// the light meets the cell's bounding cone. The atoms come sorted by their nearest
// distance to the light, and every invocation reads the same one at a time. A list has room
// for every atom in reach (u_capacity), so it never overflows. The atoms' spheres and cones,
// and the lists, are tables in images (table_image.glsl).
layout(local_size_x = 64) in;

#include "table_image.glsl"
layout(rgba32f, binding = 0) readonly uniform image2D u_slot_spheres;  // centre, vdW radius
layout(rgba32f, binding = 1) readonly uniform image2D u_slot_cones;    // direction, cos(half-angle)
layout(std430, binding = 5) readonly buffer SlotAtoms { uint slot_atoms[]; };
layout(std430, binding = 7) readonly buffer CellCones { vec4 cell_cones[]; };  // direction, cos(half-angle)
layout(rgba32f, binding = 2) writeonly uniform image2D u_list_spheres;  // as light_buffer.glsl
layout(r32i, binding = 3) writeonly uniform iimage2D u_list_atoms;
layout(std430, binding = 10) writeonly buffer ListCounts { uint list_counts[]; };

uniform int u_slots;
uniform int u_cells;
uniform uint u_capacity;

void main() {
    uint cell = gl_GlobalInvocationID.x;
    if (cell >= uint(u_cells)) return;
    vec4 cc = cell_cones[cell];
    float sin_cell = sqrt(max(1.0 - cc.w * cc.w, 0.0));
    uint base = cell * u_capacity;
    uint n = 0u;
    for (int j = 0; j < u_slots; ++j) {
        vec4 cone = imageLoad(u_slot_cones, table_texel(uint(j)));
        // The cones meet when the angle between their axes is at most the sum a + b of their
        // half-angles: always once a + b >= pi (cos a <= -cos b), else when the cosine of
        // that angle is at least cos(a + b) = cos a cos b - sin a sin b.
        float cos_sum = cone.w * cc.w - sqrt(max(1.0 - cone.w * cone.w, 0.0)) * sin_cell;
        if (cone.w > -cc.w && dot(cone.xyz, cc.xyz) < cos_sum) continue;
        imageStore(u_list_spheres, table_texel(base + n), imageLoad(u_slot_spheres, table_texel(uint(j))));
        imageStore(u_list_atoms, table_texel(base + n), ivec4(int(slot_atoms[j])));
        ++n;
    }
    list_counts[cell] = n;
}
