"""Render passes, one per module, run in order by render.renderer.Renderer.

The chain (Renderer.passes) is a plain list; a pass is any object with `name`,
`enabled(frame)`, `run(frame)` and `release()`. Lighting passes slot in between the
G-buffer passes and the light pass, writing the visibility buffer.
"""
