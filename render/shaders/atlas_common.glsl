// The occlusion atlas (render/lighting/ao/precomputed.py): one P x P patch per atom that is
// drawn, tiles in rows of u_tiles_x; texel (i, j) of a patch holds the atom's surface point in
// direction octa_decode(2 (i, j) / (P - 1) - 1) from its centre. Texel centres lie on the
// patch's border, where the octahedral fold meets itself, so a bilinear lookup inside a patch
// never reads its neighbour's (QuteMol's layout: Tarini et al. 2006; pyQuteMol OctaMap.py).
// Channels: r ambient accessibility, g directional-light visibility, b probe-light visibility.
#include "octahedral.glsl"

uniform int u_patch;    // P, texels per patch side
uniform int u_tiles_x;  // patches per atlas row

ivec2 tile_origin(int slot) { return ivec2(slot % u_tiles_x, slot / u_tiles_x) * u_patch; }

// Fractional atlas texel coordinates (texel centres at .5) of a direction in a slot's patch.
vec2 atlas_coord(int slot, vec3 direction) {
    return vec2(tile_origin(slot)) + (octa_encode(direction) * 0.5 + 0.5) * float(u_patch - 1) + 0.5;
}
