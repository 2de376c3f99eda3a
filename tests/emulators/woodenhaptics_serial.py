"""An emulated WoodenHaptics Teensy: ASCII lines over a pty, a PHANTOM-family arm, a hand.

Device side of the public description: it answers each `[ma0,ma1,ma2]` line with
`[model,enc0..enc5,error]`; bad lines set the documented error bits (256 no '[', 512
wrong field count, 1024 parse error, 8 trailing characters) and drive nothing; currents
beyond ±max are clipped; the amplifiers stay off until the calibration button is pressed
and switch off when the host has been silent for 100 ms.
"""

from __future__ import annotations

import math
import time

import numpy as np

from sasprobe.devices.kinematics import PHANTOM_MODELS, PhantomArm, tip_force
from sasprobe.devices.woodenhaptics import WATCHDOG_S, WOODEN_MODELS
from tests.emulators.physics import HeldStylus
from tests.emulators.pty_serial import PtySerialDevice


class WoodenHapticsEmulator(PtySerialDevice):
    def __init__(self, directory, *, model_code: int = 3, hand=None, start_mm=None, press_calibration=True,
                 gimbal_counts=(0, 0, 0)):
        self.model = WOODEN_MODELS[model_code]
        self.reported_model = model_code
        self.arm = PhantomArm(PHANTOM_MODELS[self.model.kinematics or "woody"])
        home = self.arm.forward(self.model.home_joint_angles)
        self.stylus = HeldStylus(home if start_mm is None else start_mm, hand=hand, mass_kg=0.12)
        self.currents = np.zeros(3)
        self.amplifiers_on = False
        self.calibrated = False
        self.count_zero = np.zeros(3)  # raw counts at the pose where the button was pressed
        self.gimbal_counts = list(gimbal_counts)
        self.error_bits = 0
        self.bad_lines = 0
        self.watchdog_trips = 0
        self.max_force_n = 0.0
        self.last_force_n = np.zeros(3)
        self.inject_before_reply: list[bytes] = []
        self.gimbal_error_bits = 0
        super().__init__(directory)
        if press_calibration:
            self.press_calibration_button()

    # mechanics ------------------------------------------------------------------------
    def _rad_per_count(self) -> np.ndarray:
        m = self.model
        return 2.0 * math.pi / np.asarray(m.counts_per_turn) * np.asarray(m.capstan_ratio) * np.asarray(m.encoder_sign)

    def _raw_counts(self) -> np.ndarray:
        q = self.arm.inverse(self.stylus.position)
        return np.round((q - np.asarray(self.model.home_joint_angles)) / self._rad_per_count())

    def replug(self) -> None:
        """Power comes back: counters restart at the present pose, torque off until the button."""
        self.calibrated = False
        self.amplifiers_on = False
        self.currents = np.zeros(3)
        self.count_zero = self._raw_counts()
        super().replug()

    def press_calibration_button(self) -> None:
        """The firmware zeroes its counters here and lets torque through from now on."""
        self.count_zero = self._raw_counts()
        self.calibrated = True

    def motor_force(self, currents_ma=None) -> np.ndarray:
        """The device-frame tip force the given (or present) currents produce, N."""
        m = self.model
        currents = self.currents if currents_ma is None else np.asarray(currents_ma, dtype=float)
        motor = currents / 1000.0 * np.asarray(m.torque_constant_nm_per_a)
        joint = motor / np.asarray(m.capstan_ratio) * np.asarray(m.encoder_sign)
        q = self.arm.inverse(self.stylus.position)
        return tip_force(self.arm.jacobian(q), joint)

    # wire -----------------------------------------------------------------------------
    def consume(self, inbox: bytes) -> bytes:
        while b"\n" in inbox:
            line, inbox = inbox.split(b"\n", 1)
            self._command(line.rstrip(b"\r"))
        if len(inbox) > 64:  # the firmware's buffer overflows
            self.error_bits |= 128
            self.bad_lines += 1
            inbox = b""
        return inbox

    def _command(self, line: bytes) -> None:
        self.last_host_message = time.monotonic()
        self.error_bits = self.gimbal_error_bits
        currents = self._parse(line)
        if currents is None:
            self.bad_lines += 1
        else:
            self.currents = np.clip(currents, -self.model.max_current_ma, self.model.max_current_ma)
            self.amplifiers_on = self.calibrated
        force = self.motor_force() if self.amplifiers_on else np.zeros(3)
        self.last_force_n = force  # at the pose the command arrived in
        self.max_force_n = max(self.max_force_n, float(np.linalg.norm(force)))
        self.stylus.advance(force)
        counts = (self._raw_counts() - self.count_zero).astype(int)
        reply = f"[{self.reported_model},{counts[0]},{counts[1]},{counts[2]}," \
                f"{self.gimbal_counts[0]},{self.gimbal_counts[1]},{self.gimbal_counts[2]},{self.error_bits}]\n"
        for junk in self.inject_before_reply:
            self.send(junk)
        self.inject_before_reply = []
        self.send(reply.encode())
        self.replies_sent += 1

    def _parse(self, line: bytes):
        text = line.decode("ascii", errors="replace")
        if not text.startswith("["):
            self.error_bits |= 256
            return None
        end = text.find("]")
        if end < 0:
            self.error_bits |= 1024
            return None
        if text[end + 1:]:
            self.error_bits |= 8
            return None
        fields = text[1:end].split(",")
        if len(fields) != 3:
            self.error_bits |= 512
            return None
        try:
            return np.array([int(f) for f in fields], dtype=float)
        except ValueError:
            self.error_bits |= 1024
            return None

    def idle(self) -> None:
        if self.amplifiers_on and self.last_host_message is not None \
                and time.monotonic() - self.last_host_message > WATCHDOG_S:
            self.amplifiers_on = False  # the 100 ms watchdog
            self.currents = np.zeros(3)
            self.watchdog_trips += 1
