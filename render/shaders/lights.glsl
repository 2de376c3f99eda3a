// The two lights every lighting effect shares: the directional light and the probe's point
// light at the probe centre. The point light falls off as the shading pass has it,
// 1 / (c + l d + q d^2), windowed to zero at u_probe_light_radius Å by (1 - (d/R)^4)^2
// (render/lighting/settings.py probe_falloff), so nothing beyond its range needs a shadow ray.
uniform vec3 u_sun_dir;          // towards the light, unit
uniform float u_sun_intensity;   // irradiance on a surface facing it
uniform int u_probe_light_on;
uniform vec3 u_probe_light_pos;  // Å
uniform float u_probe_light_radius;
uniform vec3 u_probe_light_atten;
uniform float u_probe_light_intensity;

float probe_light_falloff(float d) {
    float x = d / u_probe_light_radius;
    float window = clamp(1.0 - x * x * x * x, 0.0, 1.0);
    vec3 a = u_probe_light_atten;
    return window * window / (a.x + a.y * d + a.z * d * d);
}
