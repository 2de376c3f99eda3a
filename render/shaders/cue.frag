#version 410 core
// Probe cues (outline, ghost tip, spring, force arrow): the vertex colour at an opacity.
in LineFragment {
    vec3 position;
    vec3 color;
    float across;
    float along;
    flat vec3 tangent;
    flat ivec2 ends;
} fs_in;

uniform float u_alpha;
out vec4 o_color;

void main() {
    o_color = vec4(fs_in.color, u_alpha);
}
