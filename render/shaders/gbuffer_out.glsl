// The G-buffer's colour attachments, in this order (see render/gl/targets.py):
// albedo RGBA8, world position RGBA32F, world normal RGBA32F, (atom id, kind) RG32I.
layout(location = 0) out vec4 o_albedo;
layout(location = 1) out vec4 o_position;
layout(location = 2) out vec4 o_normal;
layout(location = 3) out ivec2 o_ids;

#include "constants.glsl"

void write_gbuffer(vec3 albedo, vec3 position, vec3 normal, int id, int kind) {
    o_albedo = vec4(albedo, 1.0);
    o_position = vec4(position, 1.0);
    o_normal = vec4(normal, 0.0);
    o_ids = ivec2(id, kind);
}
