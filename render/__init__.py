"""The render process: the app (options, source, window or headless loop), the scene, the
renderer and its passes (passes/), the GL plumbing (gl/) and the lighting family
(lighting/). It depends on molecule/ and protocol/ only: a session reaches it over the
wire or from a recording file."""
