// Random numbers and direction sampling for the Monte-Carlo passes (ray-traced AO, path
// tracing). Deterministic per (pixel, sample index), so a pass can be re-run and tested.

// PCG hash (Jarzynski & Olano, JCGT 2020).
uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

uint pixel_seed(ivec2 px, uint salt) {
    return pcg_hash(uint(px.x) + pcg_hash(uint(px.y) + pcg_hash(salt)));
}

// Sample i of Roberts' R2 low-discrepancy sequence, shifted per pixel (Cranley-Patterson
// rotation). Fixed-point arithmetic keeps it exact for any i, so accumulation over many
// frames stays low-discrepancy.
vec2 r2_sample(uint i, uint seed) {
    const uint A1 = 3242174889u;  // 2^32 / g,   g = 1.32471795724474602596 (plastic number)
    const uint A2 = 2447445413u;  // 2^32 / g^2
    uvec2 shift = uvec2(pcg_hash(seed), pcg_hash(seed ^ 0x9e3779b9u));
    uvec2 fixed_point = uvec2(i * A1, i * A2) + shift;
    return vec2(fixed_point >> 8u) * (1.0 / 16777216.0);
}

// Orthonormal basis around a unit normal (Duff et al., JCGT 2017).
mat3 basis_around(vec3 n) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float b = n.x * n.y * a;
    vec3 t1 = vec3(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    vec3 t2 = vec3(b, s + n.y * n.y * a, -n.y);
    return mat3(t1, t2, n);
}

// Cosine-weighted direction about n from u in [0, 1)^2 (pdf cos(theta) / pi).
vec3 cosine_direction(vec3 n, vec2 u) {
    float r = sqrt(u.x);
    float phi = 6.283185307179586 * u.y;
    vec3 local = vec3(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - u.x)));
    return normalize(basis_around(n) * local);
}
