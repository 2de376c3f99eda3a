"""An emulated Haply 2DIY board: binary header/ID/float32 frames over a pty, a pantograph.

Type 0 (setup) stores per-encoder offsets and resolutions and answers with the device
ID and 4 bytes; type 1 takes one torque per active motor and answers with the device ID
and one float32 angle per active encoder, quantised to the resolution. Encoders count
from the pose the board powered up in.
"""

from __future__ import annotations

import struct

import numpy as np

from sasprobe.devices.haply import TYPE_SETUP, TYPE_TORQUES
from sasprobe.devices.kinematics import PantographArm, tip_force
from tests.emulators.physics import HeldStylus
from tests.emulators.pty_serial import PtySerialDevice


class Haply2DIYEmulator(PtySerialDevice):
    def __init__(self, directory, *, device_id: int = 5, hand=None, start_mm=None):
        self.device_id = device_id
        self.arm = PantographArm()
        start_xy = self.arm.forward(np.radians([180.0, 0.0])) if start_mm is None else np.asarray(start_mm)[:2]
        self.stylus = HeldStylus((start_xy[0], start_xy[1], 0.0), hand=hand, mass_kg=0.08,
                                 hand_stiffness_n_per_mm=0.3)
        self.power_on_angles = self._true_angles()
        self.offsets_deg = None
        self.resolution = None
        self.torques = np.zeros(2)
        self.max_force_n = 0.0
        self.last_force_n = np.zeros(3)
        self.inject_before_reply: list[bytes] = []
        self.reply_override: bytes | None = None  # send this instead of the next reply
        self.ignored_bytes = 0
        super().__init__(directory, name="ttyHAPLY0")

    def _true_angles(self) -> np.ndarray:
        return self.arm.inverse(self.stylus.position[:2])

    def motor_force(self, torques=None) -> np.ndarray:
        t = self.torques if torques is None else np.asarray(torques, dtype=float)
        f = tip_force(self.arm.jacobian(self._true_angles()), t)
        return np.array([f[0], f[1], 0.0])

    def consume(self, inbox: bytes) -> bytes:
        while len(inbox) >= 2:
            header, device_id = inbox[0], inbox[1]
            kind, mask = header >> 4, header & 0xF
            channels = bin(mask).count("1")
            size = {TYPE_SETUP: 2 + 8 * channels, TYPE_TORQUES: 2 + 4 * channels}.get(kind)
            if size is None or channels == 0 or device_id != self.device_id:
                self.ignored_bytes += 1  # not a message for us: slide by one byte
                inbox = inbox[1:]
                continue
            if len(inbox) < size:
                break
            body, inbox = inbox[2:size], inbox[size:]
            values = struct.unpack(f"<{len(body) // 4}f", body)
            if kind == TYPE_SETUP:
                self.offsets_deg = np.array(values[0::2])
                self.resolution = np.array(values[1::2])
                self.send(bytes([self.device_id]) + struct.pack("<f", 1.0))
            else:
                self._exchange(np.array(values))
        return inbox

    def _exchange(self, torques: np.ndarray) -> None:
        self.torques = torques if self.offsets_deg is not None else np.zeros(2)
        force = self.motor_force()
        self.last_force_n = force  # at the pose the command arrived in
        self.max_force_n = max(self.max_force_n, float(np.linalg.norm(force)))
        self.stylus.advance(force)
        self.stylus.position[2] = 0.0
        turned = np.degrees(self._true_angles() - self.power_on_angles)
        offsets = self.offsets_deg if self.offsets_deg is not None else np.zeros(2)
        resolution = self.resolution if self.resolution is not None else np.full(2, 13824.0)
        counts = np.round(turned / 360.0 * resolution)
        angles = offsets + counts * 360.0 / resolution
        for junk in self.inject_before_reply:
            self.send(junk)
        self.inject_before_reply = []
        if self.reply_override is not None:
            self.send(self.reply_override)
            self.reply_override = None
        else:
            self.send(bytes([self.device_id]) + struct.pack("<2f", *angles))
        self.replies_sent += 1


def start_pose_mm() -> tuple[float, float, float]:
    xy = PantographArm().forward(np.radians([180.0, 0.0]))
    return (float(xy[0]), float(xy[1]), 0.0)

