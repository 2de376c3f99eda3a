"""The Haply 2DIY generations: link lengths and how each board port is set up.

From Haply's Python hAPI (`HaplyHAPI` 1.0.1 on PyPI, `HaplyHAPI.py` `Pantograph.__init__`
and the README's example; "2 for the metallic plate device, 3 for the newer plastic
device"): l = 70 mm (proximal links), L = 90 mm (distal links), d = 0 (gen 2, the two
motors on one axis) or 38 mm (gen 3) between the motor axes, and per generation which
board port drives and reads which link, its CW (0) / CCW (1) direction, the encoder's
start angle (degrees, the angle declared for the pose the handle is in at setup) and
resolution (counts per turn). The older Java/C++ hAPI (Haply-API-Java at 8e95d33,
Haply-API-cpp v1.0.0 `example/main.cpp`: l = 50, L = 70, d = 20 mm, 180°/0°, 13824) is
the earlier Haplet and is not one of these generations.

What no Haply source gives (our assumptions, devices/README.md): the workspace (a
±50 mm square around the centre below, where the Jacobian's condition number stays
under 4), the force limit (1.5 N: the board's 0.123 N·m clamp allows at least 1.59 N
in every direction everywhere in that square), the stiffness and damping limits.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from sasprobe.devices.base import DeviceLimits

CW, CCW = 0, 1
HALF_WORKSPACE_MM = 50.0


@dataclass(frozen=True)
class PortSetup:
    port: int  # the board's motor/encoder port, 1..4
    # the pantograph link it drives and reads: 1 (from the motor at x = 0) or 2 (at x = d)
    link: int
    motor_direction: int  # CW or CCW
    encoder_direction: int
    start_angle_deg: float  # the encoder offset sent at setup
    counts_per_turn: float  # the encoder resolution sent at setup


@dataclass(frozen=True)
class Generation:
    name: str
    proximal_m: float  # l
    distal_m: float  # L
    motor_spacing_m: float  # d: link 2's motor sits at (d, 0)
    ports: tuple[PortSetup, PortSetup]  # in port order, as the setup message lists them
    workspace_centre_m: tuple[float, float]  # our assumption, in the pantograph's (x, y)

    def port_for(self, link: int) -> PortSetup:
        return next(p for p in self.ports if p.link == link)

    @functools.cached_property
    def limits(self) -> DeviceLimits:
        h = HALF_WORKSPACE_MM
        # planar: the box's y (up) depth equals its others so the daemon's cube fits the plane
        return DeviceLimits(
            max_force_n=1.5,
            continuous_force_n=1.5,
            max_stiffness_n_per_mm=0.5,
            max_damping_n_s_per_m=3.0,
            workspace_min_mm=(-h, -h, -h),
            workspace_max_mm=(h, h, h),
        )


GENERATIONS: dict[str, Generation] = {
    "gen2": Generation(
        "Haply 2DIY (gen 2, metal plate)",
        0.07,
        0.09,
        0.0,
        (PortSetup(1, 2, CW, CW, -61.0, 10752.0), PortSetup(2, 1, CCW, CCW, 241.0, 10752.0)),
        workspace_centre_m=(0.0, 0.080),
    ),
    "gen3": Generation(
        "Haply 2DIY (gen 3, plastic)",
        0.07,
        0.09,
        0.038,
        (PortSetup(1, 2, CCW, CCW, 12.0, 4880.0), PortSetup(2, 1, CCW, CCW, 168.0, 4880.0)),
        workspace_centre_m=(0.019, 0.090),
    ),
}
DEFAULT_GENERATION = "gen3"
