"""The solvent probe: its default radius and the range every layer accepts.

The felt and drawn surface is the union of spheres of radius vdW + probe radius, so the
daemon's haptics, the renderer, `sasprobe sas` and `sasprobe info` all take the probe
radius from here (the protocol only type-checks it; the daemon checks the range).
"""

from __future__ import annotations

import math

DEFAULT_PROBE_RADIUS = 1.4  # Å, one water molecule
MAX_PROBE_RADIUS = 10.0  # Å; larger "probes" are not a solvent any more


def check_probe_radius(value) -> float:
    """The radius as a float in (0, MAX_PROBE_RADIUS] Å; ValueError (one line) otherwise."""
    try:
        radius = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"probe radius must be a number, got {value!r}") from None
    if not math.isfinite(radius) or radius <= 0 or radius > MAX_PROBE_RADIUS:
        raise ValueError(f"probe radius must be in (0, {MAX_PROBE_RADIUS:g}] Å, got {radius:g}")
    return radius
