"""What sasprobe assumes of each Inverse Service arm: Haply publishes no workspace box or
force limit (devices/README.md says where each number comes from).

Workspace: Haply's own tutorials keep the cursor inside a sphere about the
`arm_front_centered` origin of radius 0.08 m (C++) or 0.10 m (Python) for an Inverse3 and
0.04 m for a Minverse (docs.haply.co tutorials 05 and 06); we take the smaller radius and
declare the cube inscribed in it (half edge r/√3). Force: 2.0 N, the safety limit Isaac
Lab's Haply client sets by default (`HaplyDeviceCfg.limit_force`), for every type.
Stiffness and damping limits are ours.

Rate: the service's rate is not published either beyond "haptic control rates
(multi-kHz)" (Isaac Lab's client exchanges at 200 Hz by default,
`HaplyDeviceCfg.data_rate`). The driver never waits on the service's reply (driver.py),
so the arms run at the daemon's 1 kHz by default and up to MAX_RATE_HZ, the daemon's own
ceiling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sasprobe.devices.base import DeviceLimits

MAX_FORCE_N = 2.0
MAX_STIFFNESS_N_PER_MM = 0.5
MAX_DAMPING_N_S_PER_M = 3.0
NOMINAL_RATE_HZ = 1000.0
MAX_RATE_HZ = 4000.0


@dataclass(frozen=True)
class InverseModel:
    name: str
    workspace_radius_m: float

    @property
    def limits(self) -> DeviceLimits:
        half = self.workspace_radius_m * 1000.0 / math.sqrt(3.0)
        return DeviceLimits(
            max_force_n=MAX_FORCE_N,
            continuous_force_n=MAX_FORCE_N,
            max_stiffness_n_per_mm=MAX_STIFFNESS_N_PER_MM,
            max_damping_n_s_per_m=MAX_DAMPING_N_S_PER_M,
            workspace_min_mm=(-half, -half, -half),
            workspace_max_mm=(half, half, half),
            nominal_rate_hz=NOMINAL_RATE_HZ,
            max_rate_hz=MAX_RATE_HZ,
        )


MODELS = {  # config.type → model
    "inverse3": InverseModel("Haply Inverse3", 0.08),
    "inverse3x": InverseModel("Haply Inverse3x", 0.08),
    "minverse": InverseModel("Haply Minverse", 0.04),
}


def model_for(kind: str) -> InverseModel:
    return MODELS.get(kind, InverseModel(f"Haply {kind or 'arm'}", 0.04))


def before_open_limits() -> DeviceLimits:
    """Before the service names the arm: the smallest workspace of the table."""
    return min(MODELS.values(), key=lambda m: m.workspace_radius_m).limits
