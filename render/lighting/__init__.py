"""The lighting family on top of render/gl/: its settings, the G-buffer as the lighting reads
it, the uniform grid uploaded to the GPU and the culling, shadows, ambient occlusion (ao/),
edge cueing and progressive path tracing. The passes that put them into the frame are
render/passes/."""
