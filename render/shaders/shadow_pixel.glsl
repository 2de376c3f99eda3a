// One G-buffer pixel's visibility of a light, traced through the grid (shadows.comp, and
// shadows.frag for the pixels a depth test picks): light_visibility of the pixel's point.
#include "gbuffer_input.glsl"
#include "light_visibility.glsl"
