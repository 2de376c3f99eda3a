// The G-buffer layers the lighting passes read (render/gl/targets.py; bound to units 0..2).
//   position  rgba32f  world position (Å) in xyz
//   normal    rgba32f  unit world normal in xyz (a cap carries its plane's outward normal)
//   ids       rg32i    (atom index, kind): atom ATOM_BACKGROUND or ATOM_PROBE for those; kind KIND_*
// Lighting applies to sphere surfaces, caps and the probe; background and backbone-trace
// pixels are left alone (visibility and accessibility 1).

#include "constants.glsl"

layout(binding = 0) uniform sampler2D u_gb_position;
layout(binding = 1) uniform sampler2D u_gb_normal;
layout(binding = 2) uniform isampler2D u_gb_ids;


// Whether a pixel of this kind shows a surface the lighting shades (a sphere, a cap or the probe).
bool kind_lit(int kind) {
    return kind == KIND_SPHERE || kind == KIND_CAP || kind == KIND_PROBE;
}

bool gbuffer_lit(ivec2 px) {
    return kind_lit(texelFetch(u_gb_ids, px, 0).g);
}

// False for pixels the lighting leaves alone. The ids are fetched once: on llvmpipe each
// fetch is paid for every pixel of the pass.
bool gbuffer_fetch(ivec2 px, out vec3 position, out vec3 normal, out int atom, out int kind) {
    ivec2 ids = texelFetch(u_gb_ids, px, 0).rg;
    atom = ids.x;
    kind = ids.y;
    position = texelFetch(u_gb_position, px, 0).xyz;
    normal = normalize(texelFetch(u_gb_normal, px, 0).xyz);
    return kind_lit(kind);
}

bool gbuffer_fetch(ivec2 px, out vec3 position, out vec3 normal, out int atom) {
    int kind;
    return gbuffer_fetch(px, position, normal, atom, kind);
}

#include "ray_origin.glsl"
