#version 430 core
// The shading pass (shading.glsl) tracing the probe light's shadow rays itself through its
// light buffer (storage buffers: OpenGL 4.3).
#define TRACE_PROBE_LIGHT
#include "shading.glsl"
