// The light terms of the atoms' shading, shared by the desktop's shading pass (shading.glsl)
// and the web page's (web/page/shaders.js, which takes this text as it is): Phong with the
// scene's shininess and specular strength, and the probe light's attenuation with distance,
// windowed to 0 at its range (as render/lighting/settings.py probe_falloff).
uniform float u_shininess;
uniform float u_specular;
uniform vec3 u_probe_atten;  // constant, linear, quadratic (distance from the probe centre, Å)
uniform float u_probe_range; // Å

vec3 phong(vec3 albedo, vec3 n, vec3 v, vec3 l) {
    float diffuse = max(dot(n, l), 0.0);
    float spec = diffuse > 0.0 ? pow(max(dot(reflect(-l, n), v), 0.0), u_shininess) : 0.0;
    return diffuse * albedo + spec * u_specular;
}

float probe_attenuation(float dist) {
    float x = dist / u_probe_range;
    float window = clamp(1.0 - x * x * x * x, 0.0, 1.0);
    return window * window / (u_probe_atten.x + u_probe_atten.y * dist + u_probe_atten.z * dist * dist);
}
