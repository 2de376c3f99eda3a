#version 430 core
// Test hook: walks given rays through the grid with the same 3D-DDA the lighting passes use
// and records every cell visited with its [t_enter, t_exit], for comparison with the CPU
// walk UniformGrid.ray_cells.
layout(local_size_x = 64) in;

#include "grid_traversal.glsl"

struct Ray { vec4 origin_tmin; vec4 direction_tmax; };
layout(std430, binding = 4) readonly buffer Rays { Ray rays[]; };
layout(std430, binding = 5) writeonly buffer VisitCells { ivec4 visit_cells[]; };  // ix, iy, iz, flat id
layout(std430, binding = 6) writeonly buffer VisitT { vec2 visit_t[]; };
layout(std430, binding = 7) writeonly buffer VisitCount { int visit_count[]; };

uniform int u_n_rays;
uniform int u_max_visits;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_n_rays) return;
    Ray ray = rays[i];
    int n = 0;
    GridWalk w;
    if (walk_begin(ray.origin_tmin.xyz, ray.direction_tmax.xyz, ray.origin_tmin.w, ray.direction_tmax.w, w)) {
        do {
            if (n < u_max_visits) {
                visit_cells[i * u_max_visits + n] = ivec4(w.cell, walk_flat_cell(w));
                visit_t[i * u_max_visits + n] = vec2(w.t_enter, w.t_exit);
            }
            ++n;
        } while (walk_next(w));
    }
    visit_count[i] = n;
}
