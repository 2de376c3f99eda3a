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
