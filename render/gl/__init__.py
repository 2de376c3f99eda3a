"""GL plumbing: contexts (EGL or a window), shader programs, render targets, the molecule's
buffers, compute dispatch, uniforms and texture read-back. It knows nothing of the
lighting effects or the pass chain built on it."""
