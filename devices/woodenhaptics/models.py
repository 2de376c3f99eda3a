"""The WoodenHaptics-family models: every per-model constant, from the public host library.

Source: forsslund/hfabapi at cf00e97 (`hfab_math.h` `Kinematics::configuration::*()`,
`hfab_api.cpp` `enc_home_*` and `getPos()`/`getRot()`, `hfab_polhem.h` `L0`..`L5`). The
firmware (forsslund/woodenhaptics at 6b9ad8a, `firmware/woody_teensy_mini/
woody_teensy_mini.ino`) reports the model code (`model_polhem_2022_raw = 1`,
`model_vintage_raw = 2`, `model_woody_raw = 3`) and raw counts that are zero where its
calibration button was pressed (or where it powered up); hfabapi adds the model's home
counts to every reply. devices/README.md lists each fact with its source.

Lengths are metres and angles radians in hfabapi's frame (x toward the user, y right,
z up, origin at the configuration's `workspace_origin`), as the library computes them;
the driver converts to the device frame (kinematics.py).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from sasprobe.devices.base import DeviceLimits
from sasprobe.devices.hardware import sphere_limits

# body A (waist) + bodies B, C; or Polhem's four-bar (hfab variant 3)
SERIAL, POLHEM = ("serial", "polhem")

# hfab_polhem.h: L0 base pivot spacing, L1 body B, L2 crank, L3 coupler, L4 and L5 the
# output link behind and ahead of its pivot on body B (metres).
POLHEM_LINKS_M = (34e-3, 165e-3, 25e-3, 190e-3, 34e-3, 130.8e-3)


@dataclass(frozen=True)
class WoodenModel:
    code: int  # the firmware's model field
    name: str
    configuration: str  # the hfabapi configuration the library selects for this code
    mechanism: str  # SERIAL or POLHEM
    body_lengths_m: tuple[float, float, float]  # length_body_a..c (SERIAL: Ln, Lb, Lc)
    capstan_diameters_m: tuple[float, float, float]  # diameter_capstan_a..c
    body_diameters_m: tuple[float, float, float]  # diameter_body_a..c (the drums the cables wrap)
    # motor_and_body_aligned_a..c: True turns the body backwards
    motor_and_body_aligned: tuple[bool, bool, bool]
    counts_per_turn: tuple[int, int, int]  # cpr_encoder_a..c, quadrature counts per motor turn
    torque_constants_nm_per_a: tuple[float, float, float]  # torque_constant_motor_a..c
    home_counts: tuple[int, int, int, int, int, int]  # enc_home_*: added to every count received
    workspace_origin_m: tuple[float, float, float]  # workspace_origin_x..z, subtracted from the tip
    workspace_radius_m: float  # workspace_radius ("for application information")
    max_force_n: float  # max_linear_force
    max_stiffness_n_per_m: float  # max_linear_stiffness
    max_damping_n_s_per_m: float  # max_linear_damping
    # cpr_encoder_d, _e and getRot()'s count for f; 0: none read
    gimbal_counts_per_turn: tuple[int, int, int]
    gimbal_aligned: tuple[bool, bool]  # enc_and_body_aligned_d, _e (getRot() gives f no sign)
    gimbal_d_axis: str  # getRot(): "z" for the vintage PHANTOM, "x" otherwise

    @functools.cached_property
    def limits(self) -> DeviceLimits:
        # hfabapi has one force limit, and a workspace sphere
        return sphere_limits(
            self.workspace_radius_m,
            self.max_force_n,
            self.max_stiffness_n_per_m,
            self.max_damping_n_s_per_m,
        )


WOODEN_MODELS: dict[int, WoodenModel] = {
    1: WoodenModel(  # hfab_math.h polhem_v3(); hfab_api.cpp enc_home_polhem
        code=1,
        name="Polhem",
        configuration="polhem_v3",
        mechanism=POLHEM,
        body_lengths_m=(0.1, 0.165, 0.1308),
        capstan_diameters_m=(0.0288534, 0.0136981, 0.0137281),
        body_diameters_m=(0.175, 0.100, 0.100),
        motor_and_body_aligned=(False, True, False),
        counts_per_turn=(4096, 4096, 4096),
        torque_constants_nm_per_a=(0.0603, 0.0538, 0.0538),
        home_counts=(8312, -10366, 19764, 0, 30, 0),
        workspace_origin_m=(0.2045, 0.0, 0.0325),
        workspace_radius_m=0.150,
        max_force_n=5.0,
        max_stiffness_n_per_m=2000.0,
        max_damping_n_s_per_m=1.0,
        gimbal_counts_per_turn=(1024, 1024, 1024),
        gimbal_aligned=(False, False),
        gimbal_d_axis="x",
    ),
    2: WoodenModel(  # hfab_math.h vintage(); hfab_api.cpp enc_home_vintage
        code=2,
        name="vintage PHANTOM (WoodenHaptics retrofit)",
        configuration="vintage",
        mechanism=SERIAL,
        body_lengths_m=(0.000, 0.138, 0.112),
        capstan_diameters_m=(0.013, 0.010, 0.010),
        body_diameters_m=(0.117, 0.077, 0.077),
        motor_and_body_aligned=(True, False, True),
        counts_per_turn=(4000, 4000, 4000),
        torque_constants_nm_per_a=(0.0234, 0.0234, 0.0234),
        home_counts=(0, 7700, 0, 0, 0, 0),
        workspace_origin_m=(0.138, 0.000, -0.097),
        workspace_radius_m=0.100,
        max_force_n=5.0,
        max_stiffness_n_per_m=800.0,
        max_damping_n_s_per_m=8.0,
        gimbal_counts_per_turn=(2000, 2000, 2000),
        gimbal_aligned=(False, True),
        gimbal_d_axis="z",
    ),
    3: WoodenModel(  # hfab_math.h woodenhaptics_v2015(); hfab_api.cpp enc_home_woody
        code=3,
        name="WoodenHaptics Woody",
        configuration="woodenhaptics_v2015",
        mechanism=SERIAL,
        body_lengths_m=(0.080, 0.205, 0.245),
        capstan_diameters_m=(0.010, 0.010, 0.010),
        body_diameters_m=(0.160, 0.120, 0.120),
        motor_and_body_aligned=(False, True, True),
        counts_per_turn=(2000, 2000, 2000),
        torque_constants_nm_per_a=(0.0259, 0.0259, 0.0259),
        home_counts=(0, 0, -6000, 0, 0, 0),
        workspace_origin_m=(0.220, 0.000, 0.080),
        workspace_radius_m=0.100,
        max_force_n=5.0,
        max_stiffness_n_per_m=1000.0,
        max_damping_n_s_per_m=8.0,
        # cpr_encoder_d..f = 0: hfabapi reads no gimbal, and this firmware reports none
        gimbal_counts_per_turn=(0, 0, 0),
        gimbal_aligned=(False, False),
        gimbal_d_axis="x",
    ),
}


def known_models() -> str:
    return ", ".join(f"{m.code} {m.name}" for m in WOODEN_MODELS.values())


def _most_cautious() -> DeviceLimits:
    """What the daemon may assume before the arm has said which model it is: the smallest of
    each."""
    every = [m.limits for m in WOODEN_MODELS.values()]
    smallest_box = min(every, key=lambda lim: lim.workspace_max_mm[0])
    return DeviceLimits(
        max_force_n=min(lim.max_force_n for lim in every),
        continuous_force_n=min(lim.continuous_force_n for lim in every),
        max_stiffness_n_per_mm=min(lim.max_stiffness_n_per_mm for lim in every),
        max_damping_n_s_per_m=min(lim.max_damping_n_s_per_m for lim in every),
        workspace_min_mm=smallest_box.workspace_min_mm,
        workspace_max_mm=smallest_box.workspace_max_mm,
    )


LIMITS_BEFORE_THE_MODEL_IS_KNOWN = _most_cautious()
