"""Force law in the device frame: spring from the device tip to the proxy, plus damping.

    F = K (proxy_mm - tip_mm) - B w (v . n) n,   n = unit(proxy_mm - tip_mm)

K in N/mm, B in N·s/m (velocity in mm/s is converted), w = min(1, |proxy - tip| /
DAMPING_RAMP_MM). The damping acts only along the spring (it resists pushing in and
springing back, not sliding along the surface, which would feel like friction), and
fades in over the first DAMPING_RAMP_MM of contact so the force stays continuous at
contact onset. The result is clamped to the device's maximum force (direction kept,
`clamped` reported); a non-finite result becomes zero force with `fault` set, so no
NaN ever reaches a motor.
"""

from __future__ import annotations

import math
from typing import NamedTuple

DAMPING_RAMP_MM = 0.1


class Force(NamedTuple):
    x: float
    y: float
    z: float
    clamped: bool
    fault: bool


ZERO = Force(0.0, 0.0, 0.0, False, False)


def contact_force(
    proxy_mm: tuple[float, float, float],
    tip_mm: tuple[float, float, float],
    velocity_mm_s: tuple[float, float, float],
    stiffness_n_per_mm: float,
    damping_n_s_per_m: float,
    max_force_n: float,
) -> Force:
    sx = proxy_mm[0] - tip_mm[0]
    sy = proxy_mm[1] - tip_mm[1]
    sz = proxy_mm[2] - tip_mm[2]
    length = math.sqrt(sx * sx + sy * sy + sz * sz)
    if length == 0.0:
        return ZERO
    fx, fy, fz = stiffness_n_per_mm * sx, stiffness_n_per_mm * sy, stiffness_n_per_mm * sz
    if damping_n_s_per_m > 0.0:
        vn = (velocity_mm_s[0] * sx + velocity_mm_s[1] * sy + velocity_mm_s[2] * sz) / length
        k = damping_n_s_per_m * 1e-3 * vn * min(1.0, length / DAMPING_RAMP_MM) / length
        fx, fy, fz = fx - k * sx, fy - k * sy, fz - k * sz
    magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
    if not math.isfinite(magnitude):
        return Force(0.0, 0.0, 0.0, False, True)
    if magnitude > max_force_n:
        k = max_force_n / magnitude
        return Force(fx * k, fy * k, fz * k, True, False)
    return Force(fx, fy, fz, False, False)
