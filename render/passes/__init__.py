"""Render passes, one per module, run in order by render.renderer.Renderer.

The chain (Renderer.passes) is a plain list of passes.base.Pass objects (`name`,
`enabled(frame)`, `run(frame)`, `gbuffer_layers(frame)`, `release()`). The lighting pass
slots in between the G-buffer passes and the shading pass, writing the visibility buffer;
path tracing follows the shading pass.
"""
