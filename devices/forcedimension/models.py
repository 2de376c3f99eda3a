"""Per-model limits of the Force Dimension arms, from CHAI3D's table.

chai3d/chai3d @ 7c76b1f2, src/devices/CDeltaDevices.cpp, `cDeltaDevice::open()`: for
each `dhdGetSystemType()` value the maximum linear force (N), stiffness (N/m), damping
(N·s/m), the workspace radius (m) and an offset CHAI3D adds to every position so that
the workspace is centred (devices/README.md gives the lines). A type CHAI3D does not list
gets CHAI3D's own default (l. 749–769: the omega.3's numbers).

The declared workspace is the cube inscribed in the workspace sphere (half edge r/√3),
centred on the origin; CHAI3D gives one force limit, declared as peak and continuous.

Rates: DHD's calls answer at once (the SDK's examples and CHAI3D's haptic thread run their
loop free, as fast as the calls return), so the daemon runs these arms at 1 kHz by default
and up to MAX_RATE_HZ, its own ceiling.
"""

from __future__ import annotations

from dataclasses import dataclass

from sasprobe.devices.base import DeviceLimits
from sasprobe.devices.hardware import sphere_limits

NOMINAL_RATE_HZ = 1000.0
MAX_RATE_HZ = 4000.0


@dataclass(frozen=True)
class DhdModel:
    name: str
    max_force_n: float
    stiffness_n_per_m: float
    damping_n_s_per_m: float
    workspace_radius_m: float
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # added to dhdGetPosition (DHD frame)

    @property
    def limits(self) -> DeviceLimits:
        return sphere_limits(
            self.workspace_radius_m,
            self.max_force_n,
            self.stiffness_n_per_m,
            self.damping_n_s_per_m,
            nominal_rate_hz=NOMINAL_RATE_HZ,
            max_rate_hz=MAX_RATE_HZ,
        )


DEFAULT = DhdModel("Force Dimension arm", 12.0, 5000.0, 30.0, 0.075)
_OMEGA = dict(
    max_force_n=12.0, stiffness_n_per_m=5000.0, damping_n_s_per_m=30.0, workspace_radius_m=0.075
)
_LAMBDA = dict(
    max_force_n=12.0, stiffness_n_per_m=8000.0, damping_n_s_per_m=30.0, workspace_radius_m=0.1125
)

# dhdGetSystemType() → model (dhdc.h DHD_DEVICE_* values)
MODELS: dict[int, DhdModel] = {
    63: DhdModel("delta.3", 20.0, 5000.0, 30.0, 0.15),
    33: DhdModel("omega.3", **_OMEGA),
    34: DhdModel("omega.6 (right)", **_OMEGA),
    36: DhdModel("omega.6 (left)", **_OMEGA),
    35: DhdModel("omega.7 (right)", **_OMEGA),
    37: DhdModel("omega.7 (left)", **_OMEGA),
    104: DhdModel("sigma.7 (right)", 12.0, 4000.0, 30.0, 0.075, (-0.01, 0.02, 0.0)),
    105: DhdModel("sigma.7 (left)", 12.0, 4000.0, 30.0, 0.075, (-0.01, -0.02, 0.0)),
    108: DhdModel("lambda.7 (right)", **_LAMBDA),
    109: DhdModel("lambda.7 (left)", **_LAMBDA),
    60: DhdModel("Novint Falcon (through DHD)", 8.0, 3000.0, 20.0, 0.04),
}
# Types the headers name but CHAI3D's table does not: CHAI3D's default limits, their own name.
UNLISTED_NAMES = {
    64: "delta.6",
    206: "sigma.3",
    203: "lambda.3",
    131: "lambda.6 (right)",
    132: "lambda.6 (left)",
    91: "custom",
}


def model_for(system_type: int) -> DhdModel:
    if system_type in MODELS:
        return MODELS[system_type]
    name = UNLISTED_NAMES.get(system_type, f"Force Dimension type {system_type}")
    return DhdModel(
        name,
        DEFAULT.max_force_n,
        DEFAULT.stiffness_n_per_m,
        DEFAULT.damping_n_s_per_m,
        DEFAULT.workspace_radius_m,
    )


def before_open_limits() -> DeviceLimits:
    """What the daemon gets before the model is known: the smallest of each limit over the table."""
    every = list(MODELS.values()) + [DEFAULT]
    return DhdModel(
        "",
        min(m.max_force_n for m in every),
        min(m.stiffness_n_per_m for m in every),
        min(m.damping_n_s_per_m for m in every),
        min(m.workspace_radius_m for m in every),
    ).limits
