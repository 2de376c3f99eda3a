"""The renderer's passes, one a module, run in order by render/renderer.py.

Each is a passes.base.Pass (`name`, `layer`, `enabled(frame)`, `run(frame)`,
`footprint(frame)`, `exported_arrays(frame)`, `release()`): it takes what it draws from the
frame (passes.base.Frame) and the frame plan, and holds no caching policy of its own. The
lighting passes slot in when the lighting is installed (Renderer.install_lighting).
"""
