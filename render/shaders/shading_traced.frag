#version 430 core
// The shading pass (shading.glsl) tracing the probe light's shadow rays itself through its
// light buffer (storage buffers: OpenGL 4.3), reading the G-buffer as images.
#define TRACE_PROBE_LIGHT
#define GBUFFER_IMAGES
#include "shading.glsl"
