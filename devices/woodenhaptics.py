"""WoodenHaptics / Polhem-style arms on a Teensy over USB serial (CDC-ACM, ASCII lines).

Implemented from the public description of the open firmware (research notes §3):

- host → device: `[ma0,ma1,ma2]` + newline, the three motor currents in mA (±6000 is the
  ESCON amplifier's range; each model may allow less);
- device → host: `[model,enc0,enc1,enc2,enc3,enc4,enc5,error]` + newline: the model
  (1 Polhem 2022, 2 vintage PHANTOM retrofit, 3 Woody), three arm encoders, three gimbal
  encoders and an error field (8 trailing characters, 128 buffer full, 256 no '[',
  512 wrong field count, 1024 parse error: our command was refused; 1/2/4 gimbal I²C);
- a 100 ms watchdog disables the amplifiers when commands stop, and torque stays off
  until the calibration button has been pressed; the counters are zero at the pose where
  it was pressed (the model's home pose) and the host adds the home offsets.

Encoder counts → joint angles (per-model table: counts per turn, capstan ratio, sign,
home angles) → PHANTOM-family forward kinematics; force → τ = Jᵀ·F → motor torque
(× capstan ratio) → current (÷ torque constant), scaled by one factor at the current limit.

Calibration (zero pose): the firmware cannot tell the host that its button was pressed,
so the driver reports `calibrated=False` until it has seen the arm resting in the home
pose (every arm encoder within `HOME_TOLERANCE_RAD` of zero for `home_frames` replies in
a row) — start sasprobe with the arm in its home pose, or put it there once.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from sasprobe.devices.base import DeviceFault, DeviceInfo, DeviceLimits, DeviceOpenError
from sasprobe.devices.kinematics import PHANTOM_MODELS, KinematicsError, PhantomArm, scale_to_limit
from sasprobe.devices.serial_arm import SerialArm
from sasprobe.devices.support import clamp_force, quaternion_about, quaternion_multiply
from sasprobe.devices.transports import LineReader

log = logging.getLogger("sasprobe.devices.woodenhaptics")

FIELDS = 8
WATCHDOG_S = 0.100
HOME_TOLERANCE_RAD = math.radians(2.0)

# Error bits of the device's reply.
ERR_GIMBAL_I2C = 0x1 | 0x2 | 0x4
ERR_COMMAND_REFUSED = 8 | 128 | 256 | 512 | 1024
ERROR_NAMES = {1: "gimbal 0 I2C", 2: "gimbal 1 I2C", 4: "gimbal 2 I2C", 8: "trailing characters",
               128: "buffer full", 256: "no '['", 512: "wrong field count", 1024: "parse error"}


@dataclass(frozen=True)
class WoodenModel:
    """One model's drive train and limits. Numbers are nominal builds: measure yours."""

    code: int
    name: str
    kinematics: str | None  # key into PHANTOM_MODELS; None when not publicly described
    counts_per_turn: tuple[float, float, float]  # encoder counts per motor turn (quadrature)
    capstan_ratio: tuple[float, float, float]  # joint turns per motor turn (capstan ∅ / drum ∅)
    encoder_sign: tuple[int, int, int]
    torque_constant_nm_per_a: tuple[float, float, float]
    max_current_ma: float
    home_joint_angles: tuple[float, float, float]  # joint angles (rad) where the counters are zero
    gimbal_counts_per_turn: float
    limits: DeviceLimits


WOODEN_MODELS: dict[int, WoodenModel] = {
    1: WoodenModel(1, "Polhem 2022", None, (2048, 2048, 2048), (0.1, 0.1, 0.1), (1, 1, 1),
                   (0.0259, 0.0259, 0.0259), 6000.0, (0.0, 0.0, 0.0), 4096,
                   DeviceLimits(5.0, 2.0, 1.0, 5.0, (-80, -60, -60), (80, 60, 60))),
    2: WoodenModel(2, "vintage PHANTOM (WoodenHaptics retrofit)", "vintage-phantom", (2000, 2000, 2000),
                   (0.1, 0.1, 0.1), (1, 1, 1), (0.0255, 0.0255, 0.0255), 3000.0, (0.0, 0.0, 0.0), 4096,
                   DeviceLimits(max_force_n=5.0, continuous_force_n=1.5, max_stiffness_n_per_mm=1.0,
                                max_damping_n_s_per_m=5.0, workspace_min_mm=(-80.0, -60.0, -40.0),
                                workspace_max_mm=(80.0, 60.0, 40.0))),
    3: WoodenModel(3, "WoodenHaptics Woody", "woody", (2000, 2000, 2000), (0.0653, 0.0653, 0.0653),
                   (1, 1, 1), (0.0259, 0.0259, 0.0259), 6000.0, (0.0, 0.0, 0.0), 4096,
                   DeviceLimits(max_force_n=8.0, continuous_force_n=3.0, max_stiffness_n_per_mm=1.5,
                                max_damping_n_s_per_m=10.0, workspace_min_mm=(-110.0, -80.0, -60.0),
                                workspace_max_mm=(110.0, 80.0, 60.0))),
}

DEFAULT_LIMITS = WOODEN_MODELS[3].limits  # before the arm has said which model it is


class LineError(ValueError):
    pass


def encode_command(currents_ma) -> bytes:
    return ("[" + ",".join(str(int(round(c))) for c in currents_ma) + "]\n").encode("ascii")


def parse_reply(line: bytes) -> tuple[int, list[int], int]:
    """(model, six encoder counts, error bits) of one reply line; LineError if malformed."""
    try:
        text = line.decode("ascii").strip()
    except UnicodeDecodeError:
        raise LineError("not ASCII") from None
    if not (text.startswith("[") and text.endswith("]")):
        raise LineError("not framed by '[' ... ']'")
    fields = text[1:-1].split(",")
    if len(fields) != FIELDS:
        raise LineError(f"{len(fields)} fields, expected {FIELDS}")
    try:
        values = [int(f) for f in fields]
    except ValueError:
        raise LineError("a field is not an integer") from None
    return values[0], values[1:7], values[7]


def describe_errors(bits: int) -> str:
    return ", ".join(name for bit, name in ERROR_NAMES.items() if bits & bit) or "none"


class WoodenHapticsDevice(SerialArm):
    scheme = "woodenhaptics"

    def __init__(self, port: str | None, *, read_timeout_s: float = 0.05, home_frames: int = 50):
        super().__init__(port, read_timeout_s=read_timeout_s)
        self.home_frames = home_frames
        self.model: WoodenModel | None = None
        self.arm: PhantomArm | None = None
        self._lines = LineReader(self.transport)
        self._q = np.zeros(3)
        self._position = np.zeros(3)
        self._home_streak = 0
        self.calibrated = False
        self.device_error_bits = 0
        self.refused_commands = 0
        self.gimbal_errors = 0
        self.watchdog_gaps = 0

    @property
    def info(self) -> DeviceInfo:
        model = self.model
        return DeviceInfo(
            kind=self.scheme, model=model.name if model else "WoodenHaptics arm",
            limits=model.limits if model else DEFAULT_LIMITS, serial=self.port,
            details={"model_code": model.code if model else None, "rejected_frames": self.rejected_frames,
                     "device_error_bits": self.device_error_bits,
                     "device_errors": describe_errors(self.device_error_bits),
                     "refused_commands": self.refused_commands, "watchdog_gaps": self.watchdog_gaps},
        )

    def _handshake(self) -> None:
        self._lines.clear()
        self.transport.discard_input()
        self._home_streak = 0
        self.calibrated = False
        self._write_command()
        self._receive_or_fault()  # learns the model

    def _command_bytes(self) -> bytes:
        if self._last_sent and time.monotonic() - self._last_sent > WATCHDOG_S:
            # the firmware's watchdog has switched the amplifiers off; resume from zero
            self.watchdog_gaps += 1
            log.info("no command for more than %d ms: the arm's watchdog disabled its amplifiers",
                     WATCHDOG_S * 1000)
            return encode_command(np.zeros(3))
        if not (self.calibrated and self.model):
            return encode_command(np.zeros(3))
        return encode_command(self.currents_for(self.force))

    def _receive(self, deadline: float):
        while True:
            line = self._lines.read_line(deadline)
            if line is None:
                return None
            try:
                model_code, counts, errors = parse_reply(line)
            except LineError:
                self.rejected_frames += 1
                continue
            if self.model is None:
                self._adopt_model(model_code)
            elif model_code != self.model.code:
                self.rejected_frames += 1
                continue
            self._note_errors(errors)
            return counts

    def _adopt_model(self, code: int) -> None:
        model = WOODEN_MODELS.get(code)
        if model is None:
            raise DeviceOpenError(f"the arm on {self.port} reports model {code}, which sasprobe does not know "
                                  f"(known: {', '.join(f'{m.code} {m.name}' for m in WOODEN_MODELS.values())})")
        if model.kinematics is None:
            raise DeviceOpenError(f"the arm on {self.port} is a {model.name} (model {code}): its kinematics "
                                  "are not publicly described, so sasprobe cannot drive it yet")
        self.model = model
        self.arm = PhantomArm(PHANTOM_MODELS[model.kinematics])

    def _note_errors(self, bits: int) -> None:
        if bits & ERR_COMMAND_REFUSED:
            self.refused_commands += 1
        if bits & ERR_GIMBAL_I2C:
            self.gimbal_errors += 1
        if bits != self.device_error_bits:
            if bits:
                log.warning("%s reports errors: %s", self.port, describe_errors(bits))
            self.device_error_bits = bits

    # counts ↔ angles ↔ currents -------------------------------------------------------
    def _rad_per_count(self) -> np.ndarray:
        m = self.model
        return (2.0 * math.pi / np.asarray(m.counts_per_turn) * np.asarray(m.capstan_ratio)
                * np.asarray(m.encoder_sign))

    def joint_angles(self, counts) -> np.ndarray:
        return np.asarray(self.model.home_joint_angles) + np.asarray(counts[:3], dtype=float) * self._rad_per_count()

    def currents_for(self, force_n) -> np.ndarray:
        """Motor currents (mA) rendering a device-frame force at the current pose."""
        m = self.model
        force = clamp_force(force_n, m.limits.max_force_n)
        try:
            joint = self.arm.torques(self._q, force)
        except (KinematicsError, np.linalg.LinAlgError):
            return np.zeros(3)
        motor = joint * np.asarray(m.capstan_ratio) * np.asarray(m.encoder_sign)
        currents = motor / np.asarray(m.torque_constant_nm_per_a) * 1000.0
        scaled, _ = scale_to_limit(currents, m.max_current_ma)
        return np.round(scaled)

    def _state_from(self, counts, t_ns: int):
        self._q = self.joint_angles(counts)
        arm_at_home = np.all(np.abs(np.asarray(counts[:3]) * self._rad_per_count()) <= HOME_TOLERANCE_RAD)
        self._home_streak = self._home_streak + 1 if arm_at_home else 0
        if self._home_streak >= self.home_frames and not self.calibrated:
            self.calibrated = True
            log.info("%s: arm seen resting in its home pose; force output enabled", self.port)
        try:
            self._position = self.arm.forward(self._q)
        except KinematicsError as exc:  # cannot happen for finite angles; kept for safety
            raise DeviceFault(str(exc)) from None
        gimbal = np.asarray(counts[3:6], dtype=float) * 2.0 * math.pi / self.model.gimbal_counts_per_turn
        # yaw (waist + gimbal 0) about Y (up), pitch (gimbal 1) about X, roll (gimbal 2) about Z
        orientation = quaternion_multiply(
            quaternion_multiply(quaternion_about((0, 1, 0), self._q[0] + gimbal[0]), quaternion_about((1, 0, 0), gimbal[1])),
            quaternion_about((0, 0, 1), gimbal[2]))
        return self._position.copy(), orientation, 0, self.calibrated


def create(argument: str | None = None, **options) -> WoodenHapticsDevice:
    """`woodenhaptics:PORT`. Options: read_timeout_s, home_frames."""
    return WoodenHapticsDevice(argument, read_timeout_s=float(options.get("read_timeout_s", 0.05)),
                               home_frames=int(options.get("home_frames", 50)))
