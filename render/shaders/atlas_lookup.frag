#version 430 core
// The occlusion atlas looked up per G-buffer pixel (atlas_lookup.glsl), drawn at the far
// plane through a depth test against the renderer's G-buffer (render/gl/depth_picked.py):
// the surfaces look up, the background (BACKGROUND_ONLY) writes what look_up gives it, 1.
// The test must come first: the terms are image stores, which a late test would not stop.
layout(early_fragment_tests) in;

#include "atlas_lookup.glsl"

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
#ifdef BACKGROUND_ONLY
    store_terms(px, 1.0, 1.0, 1.0);
#else
    look_up(px);
#endif
}
