"""The Novint Falcon's numbers: mechanism, encoders, motors, frame, limits (one home each).

Every value comes from libnifalcon (github.com/libnifalcon/libnifalcon, commit f7c727a);
`devices/README.md` ("Novint Falcon") lists file and symbol for each. Where libnifalcon
leaves a number open the comment says what we assume.
"""

from __future__ import annotations

import math

import numpy as np
from sasprobe.devices.base import DeviceLimits

# USB: FalconComm.h FALCON_VENDOR_ID / FALCON_PRODUCT_ID; FalconCommLibUSB.cpp endpoints.
VENDOR_ID, PRODUCT_ID = 0x0403, 0xCB48
EP_OUT, EP_IN = 0x02, 0x81

# Stamper geometry, metres (FalconGeometry.h a..s; Stamper's thesis p. 30 names them).
THIGH_M = 0.060  # a: leg base → knee
SHIN_M = 0.1025  # b: shin parallelogram side
EFFECTOR_U_M = 0.01443  # c: effector centre → shin joint, along the leg's u axis
EFFECTOR_JOINT_M = 0.01125  # d: shin → effector joint bar
KNEE_JOINT_M = 0.01125  # e = d: knee → shin joint bar
EFFECTOR_V_M = -0.025  # f: effector centre → shin joint, along the leg's v axis
BASE_U_M = 0.0400  # r: origin → leg base, u
BASE_V_M = -0.02309  # s: origin → leg base, v
LEG_ROTATION_RAD = math.pi / 12.0  # OFFSET_ANGLE: every leg turned 15° from the desk plane
# phy: leg azimuths, looking at the Falcon from the front, from the top leg clockwise
LEG_AZIMUTH_RAD = np.array([math.pi / 2.0, -math.pi / 6.0, -5.0 * math.pi / 6.0]) + LEG_ROTATION_RAD

# Encoders (FalconKinematic.h getTheta): 320 slots × 4 counts per motor turn; the motor
# shaft (14.25 mm) drives the thigh's 110 mm drum; count 0 is the thigh at 35° once homed.
ENCODER_COUNTS_PER_TURN = 320 * 4
SHAFT_DIAMETER_M = 0.01425
DRUM_DIAMETER_M = 0.110
THIGH_RAD_PER_COUNT = 2.0 * math.pi / ENCODER_COUNTS_PER_TURN * SHAFT_DIAMETER_M / DRUM_DIAMETER_M
THIGH_AT_ZERO_COUNT_RAD = math.radians(35.0)

# Motors (FalconKinematicStamper.cpp getForces): command = −10000 × thigh torque (N·m);
# the headers document the command range as ±4096 (FalconKinematicStamper.h). The
# electrical meaning of one count is not published: we take libnifalcon's scale as is.
MOTOR_COUNTS_PER_NM = -10000.0
MOTOR_COMMAND_LIMIT = 4096

# The device frame is libnifalcon's (x right, y up, z toward the user, seen from the
# front) moved to the workspace centre its examples use (z = 0.11 m: FalconSphereTest.cpp,
# barrow_mechanics/main.cpp) and scaled to millimetres. getWorkspaceOrigin() says
# z = 0.150 m, 33 mm from the outer end of the model's reach (0.183 m): we follow the examples.
WORKSPACE_CENTRE_M = np.array([0.0, 0.0, 0.110])

FALCON_LIMITS = DeviceLimits(
    max_force_n=8.0,  # not in libnifalcon: CHAI3D's Falcon record (Novint: > 8.9 N)
    continuous_force_n=4.0,  # not published: we budget half the peak
    max_stiffness_n_per_mm=3.0,  # CHAI3D: 3000 N/m
    max_damping_n_s_per_m=20.0,  # CHAI3D
    # ±40 mm around the centre: inside the Stamper model's reach everywhere, Jacobian
    # condition number < 5 (tests/test_devices_falcon.py checks both)
    workspace_min_mm=(-40.0, -40.0, -40.0),
    workspace_max_mm=(40.0, 40.0, 40.0),
    nominal_rate_hz=1000.0,
)
