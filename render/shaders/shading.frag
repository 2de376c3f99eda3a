#version 410 core
// The shading pass (shading.glsl) where OpenGL 4.1 is all there is, or the lighting hands
// over the probe light's visibility as a texture.
#include "shading.glsl"
