#version 410 core
#include "gbuffer_out.glsl"

in MeshData {
    vec3 position;
    vec3 normal;
    flat vec3 color;
    flat int id;
} fs_in;

void main() {
    write_gbuffer(fs_in.color, fs_in.position, normalize(fs_in.normal), fs_in.id, KIND_SPHERE);
}
