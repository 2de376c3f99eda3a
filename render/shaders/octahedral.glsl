// Octahedral map of the unit sphere onto the square [-1, 1]^2 (Praun & Hoppe 2003); encode as
// in Cigolle et al., "A Survey of Efficient Representations for Independent Unit Vectors",
// JCGT 3(2), 2014: the upper half (z > 0) is the inner diamond |x| + |y| <= 1, the lower half
// folds out over the four corners. The decode, needed only for the atlas's texel
// directions, is done once on the CPU (render/lighting/ao/precomputed.py texel_normals).
vec2 octa_sign(vec2 v) { return vec2(v.x >= 0.0 ? 1.0 : -1.0, v.y >= 0.0 ? 1.0 : -1.0); }

vec2 octa_encode(vec3 v) {
    vec2 p = v.xy / (abs(v.x) + abs(v.y) + abs(v.z));
    return v.z < 0.0 ? (1.0 - abs(p.yx)) * octa_sign(p) : p;
}
