// The two lights every lighting effect shares: the directional light and the probe's point
// light at the probe centre, which reaches u_probe_light_radius Å and fades to zero there.
uniform vec3 u_sun_dir;          // towards the light, unit
uniform float u_sun_intensity;   // irradiance on a surface facing it
uniform int u_probe_light_on;
uniform vec3 u_probe_light_pos;  // Å
uniform float u_probe_light_radius;
uniform float u_probe_light_intensity;

float probe_light_falloff(float d) {
    float x = clamp(1.0 - d / u_probe_light_radius, 0.0, 1.0);
    return x * x;
}
