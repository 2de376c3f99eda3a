#version 410 core
// Which pixels lie within u_reach pixels of a surface of the G-buffer (its ids' kind not
// background): a box dilation in two draws over the frame, the rows (ROWS: into a
// one-channel texture) then the columns (written as depth: 0 near a surface, 1 elsewhere).
// The FXAA pass tests against it (render/passes/fxaa.py): a pixel farther than its reach
// from every surface reads only background, so FXAA leaves it as the kept picture has it.
#include "constants.glsl"

uniform int u_reach;
#ifdef ROWS
uniform isampler2D u_ids;
out vec4 o_near;
#else
uniform sampler2D u_rows;
#endif

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    bool near = false;
#ifdef ROWS
    int last = textureSize(u_ids, 0).x - 1;
    for (int k = -u_reach; k <= u_reach; ++k)
        near = near || texelFetch(u_ids, ivec2(clamp(px.x + k, 0, last), px.y), 0).y != KIND_BACKGROUND;
    o_near = vec4(near ? 1.0 : 0.0);
#else
    int last = textureSize(u_rows, 0).y - 1;
    for (int k = -u_reach; k <= u_reach; ++k)
        near = near || texelFetch(u_rows, ivec2(px.x, clamp(px.y + k, 0, last)), 0).r > 0.5;
    gl_FragDepth = near ? 0.0 : 1.0;
#endif
}
