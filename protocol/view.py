"""How a renderer shows a session, as every renderer (the desktop window, the browser page)
reads it from the scene and the pose.

The workspace view looks along the device's −z: the scene's `view.rotation` holds the device
axes in the molecule frame (columns x, y, z), and the camera looks along −(third column) with
the second up, so device x, y and z are the screen's right, up and toward the viewer (the
convention of CHAI3D and OpenHaptics applications). The camera frames a sphere of
FRAME_RADIUS cube half edges around the navigation cube's centre: at the distance where that
sphere, grown by FIT_MARGIN, just fits the picture's narrower field of view. The cube's front
face then fills about 78 % of the picture's shorter side, and what lies behind the cube shows
around it rather than only through it.

The force arrow starts on the probe's surface and is ARROW_RADII probe radii long at the
device's continuous force rating (scaled with the force, up to its peak rating). The lines
(the backbone trace, the cube's edges) have the widths below.
"""

from __future__ import annotations

import numpy as np

DEFAULT_FOV = 40.0  # degrees, vertical
FIT_MARGIN = 1.05  # a little air around a fitted bounding sphere
FRAME_RADIUS = 1.5  # the workspace view frames this many cube half edges around its centre
ARROW_RADII = 3.0  # the force arrow's length at the continuous rating, in probe radii
TRACE_RADIUS = 0.35  # Å: the backbone trace is drawn as tubes this thick ...
TRACE_MIN_PX = 2.0  # ... and at least this many pixels wide
WIRE_PX = 1.5  # the navigation cube's edges, pixels wide


def view_axes(scene: dict | None) -> np.ndarray:
    """The workspace view's rotation of a scene message (identity for a daemon without one)."""
    view = (scene or {}).get("view")
    if not isinstance(view, dict) or "rotation" not in view:
        return np.eye(3)
    axes = np.asarray(view["rotation"], dtype=np.float64)
    return axes if axes.shape == (3, 3) and np.all(np.isfinite(axes)) else np.eye(3)


def conventions() -> dict:
    """The numbers above, for a renderer written in another language (the browser page)."""
    return {
        "fov_deg": DEFAULT_FOV,
        "fit_margin": FIT_MARGIN,
        "frame_radius": FRAME_RADIUS,
        "arrow_radii": ARROW_RADII,
        "trace_radius": TRACE_RADIUS,
        "trace_min_px": TRACE_MIN_PX,
        "wire_px": WIRE_PX,
    }
