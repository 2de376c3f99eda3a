// The G-buffer layers the lighting passes read (bound to texture units 0..2).
//   position  rgba32f  world position (Å) in xyz
//   normal    rgba     unit world normal in xyz (a cap carries its plane's normal)
//   atom      r32i     atom index; -1 background; -2 the probe sphere

layout(binding = 0) uniform sampler2D u_gb_position;
layout(binding = 1) uniform sampler2D u_gb_normal;
layout(binding = 2) uniform isampler2D u_gb_atom;

const int ATOM_BACKGROUND = -1;
const int ATOM_PROBE = -2;

// False for background pixels.
bool gbuffer_fetch(ivec2 px, out vec3 position, out vec3 normal, out int atom) {
    atom = texelFetch(u_gb_atom, px, 0).r;
    position = texelFetch(u_gb_position, px, 0).xyz;
    normal = normalize(texelFetch(u_gb_normal, px, 0).xyz);
    return atom != ATOM_BACKGROUND;
}

// Rays leave a surface from just outside it: offset along the normal by an epsilon that
// grows with the coordinates' magnitude (float32 spacing), as Waechter & Binder (RTG ch. 6)
// advise. The source atom is also excluded from every query, which for a convex solid
// (a sphere, or a sphere cut by planes) removes self-intersection exactly; the offset only
// matters at seams between neighbouring atoms.
uniform float u_ray_eps_abs;  // Å
uniform float u_ray_eps_rel;  // per Å of |coordinate|

vec3 ray_origin(vec3 position, vec3 normal) {
    float scale = max(max(abs(position.x), abs(position.y)), abs(position.z));
    return position + normal * (u_ray_eps_abs + u_ray_eps_rel * scale);
}
