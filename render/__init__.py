"""The render process: the app (options, source, window or headless loop), the scene, the
renderer and its passes (passes/), the GL plumbing (gl/), the lighting (lighting/), the
interactive window (window/) and following a daemon (follow/). It depends on molecule/ and
protocol/ only: a session reaches it over the wire or from a recording file."""
