"""Haply 2DIY (hAPI board) over USB serial: binary header / device-ID / float32 frames.

Implemented from the public description (research notes §3):

- every message starts with a header byte `(type << 4) | port mask` (a bit per active
  motor/encoder port, 1-4) and the device-ID byte, followed by one little-endian
  float32 per active channel (setup: two per encoder);
- type 0, setup: per active encoder its angle offset (degrees) and resolution (counts per
  turn; default 13824, offsets 180° and 0°); the board answers with 5 bytes, the device
  ID and 4 bytes we do not interpret;
- type 1, torques out (N·m per active motor), angles back: the device ID and one float32
  angle (degrees) per active encoder.

Our conventions (check them on your board): angles counter-clockwise from +x with the
handle on the −y side; torques positive counter-clockwise at the joint. Positions are
reported relative to the centre of the usable area (`WORKSPACE_CENTRE_XY_MM` in the
pantograph's frame). The 2DIY is planar: z is always 0 and forces along z are dropped;
its workspace box gets a z depth equal to its y depth so that the daemon's navigation
cube (fitted to the box's smallest side) maps onto it, and the probe then moves in the
cube's mid-plane.

Calibration: the setup message declares the pose the arm is in as the start pose (left
link pointing left at 180°, right link pointing right at 0°), so the handle must rest
there when sasprobe opens the device; `calibrated` is False until the board has
acknowledged the setup.
"""

from __future__ import annotations

import struct
import time

import numpy as np

from sasprobe.devices.base import DeviceFault, DeviceInfo, DeviceLimits
from sasprobe.devices.kinematics import KinematicsError, PantographArm, scale_to_limit
from sasprobe.devices.serial_arm import SerialArm
from sasprobe.devices.support import clamp_force

TYPE_SETUP, TYPE_TORQUES = 0, 1
DEFAULT_DEVICE_ID = 5
DEFAULT_PORTS = (1, 2)
DEFAULT_OFFSETS_DEG = (180.0, 0.0)
DEFAULT_RESOLUTION = 13824.0
SETUP_REPLY_SIZE = 5
MAX_ABS_ANGLE_DEG = 1080.0  # anything beyond three turns is garbage, not an angle
QUIET_S = 0.005  # a partial reply with no new bytes for this long is a short frame

# Not published for the 2DIY: conservative figures for a small desktop pantograph.
TORQUE_LIMIT_NM = 0.25
WORKSPACE_CENTRE_XY_MM = np.array([0.0, -75.0])  # the usable area is x ±60, y −110..−40 mm
HAPLY_2DIY_LIMITS = DeviceLimits(
    max_force_n=3.0,
    continuous_force_n=1.0,
    max_stiffness_n_per_mm=0.5,
    max_damping_n_s_per_m=3.0,
    workspace_min_mm=(-60.0, -35.0, -35.0),
    workspace_max_mm=(60.0, 35.0, 35.0),  # z: planar, see above
    nominal_rate_hz=1000.0,
)


def port_mask(ports) -> int:
    mask = 0
    for p in ports:
        if not 1 <= p <= 4:
            raise ValueError(f"port {p} is not 1-4")
        mask |= 1 << (p - 1)
    return mask


def encode_message(kind: int, mask: int, device_id: int, values) -> bytes:
    return bytes([(kind << 4) | mask, device_id]) + struct.pack(f"<{len(values)}f", *values)


def decode_angles(reply: bytes, device_id: int, channels: int) -> np.ndarray | None:
    """Angles (degrees) of a type-1 reply, or None if it is not one from our board."""
    if len(reply) != 1 + 4 * channels or reply[0] != device_id:
        return None
    angles = np.array(struct.unpack(f"<{channels}f", reply[1:]), dtype=float)
    if not np.all(np.isfinite(angles)) or np.any(np.abs(angles) > MAX_ABS_ANGLE_DEG):
        return None
    return angles


class Haply2DIYDevice(SerialArm):
    scheme = "haply"

    def __init__(self, port: str | None, *, read_timeout_s: float = 0.05, device_id: int = DEFAULT_DEVICE_ID,
                 ports=DEFAULT_PORTS, offsets_deg=DEFAULT_OFFSETS_DEG, resolution: float = DEFAULT_RESOLUTION):
        super().__init__(port, read_timeout_s=read_timeout_s)
        self.device_id = device_id
        self.ports = tuple(ports)
        self.mask = port_mask(self.ports)
        self.offsets_deg = tuple(offsets_deg)
        self.resolution = resolution
        self.arm = PantographArm()
        self._theta = np.radians(self.offsets_deg)
        self._position = np.zeros(3)
        self._buffer = b""
        self.calibrated = False

    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(kind=self.scheme, model="Haply 2DIY", limits=HAPLY_2DIY_LIMITS, serial=self.port,
                          details={"device_id": self.device_id, "ports": list(self.ports),
                                   "rejected_frames": self.rejected_frames, "planar": True})

    # wire -----------------------------------------------------------------------------
    def _handshake(self) -> None:
        self.calibrated = False
        self.transport.discard_input()
        self._buffer = b""
        setup = []
        for offset in self.offsets_deg:
            setup += [offset, self.resolution]
        deadline = time.monotonic() + self.read_timeout_s * 4
        self.transport.write(encode_message(TYPE_SETUP, self.mask, self.device_id, setup))
        while True:
            reply = self._read_exact(SETUP_REPLY_SIZE, deadline)
            if reply is None:
                raise DeviceFault(f"no answer to the setup message within {self.read_timeout_s * 4 * 1000:.0f} ms")
            if reply[0] == self.device_id:
                break
            self.rejected_frames += 1
            self.transport.discard_input()
            self._buffer = b""
        self.calibrated = True

    def _send(self) -> None:
        if self._outstanding == 0 and (self._buffer or self._stale_input()):
            # bytes nobody asked for: binary frames cannot resynchronise on them, so drop them
            self.rejected_frames += 1
            self.transport.discard_input(quiet_s=0.0005, max_s=0.005)
            self._buffer = b""
        super()._send()

    def _command_bytes(self) -> bytes:
        torques = self.torques_for(self.force) if self.calibrated else np.zeros(2)
        return encode_message(TYPE_TORQUES, self.mask, self.device_id, list(torques))

    def _stale_input(self) -> bool:
        return bool(self.transport.read(4096, 0.0))

    def _read_exact(self, size: int, deadline: float) -> bytes | None:
        """`size` bytes, None at the deadline; a short frame followed by silence comes back short."""
        last_arrival = time.monotonic()
        while len(self._buffer) < size:
            now = time.monotonic()
            if now >= deadline:
                return None
            if self._buffer and now - last_arrival > QUIET_S:
                short, self._buffer = self._buffer, b""
                return short
            chunk = self.transport.read(4096, min(deadline - now, QUIET_S))
            if chunk:
                self._buffer += chunk
                last_arrival = time.monotonic()
        reply, self._buffer = self._buffer[:size], self._buffer[size:]
        return reply

    def _receive(self, deadline: float):
        channels = len(self.ports)
        while True:
            reply = self._read_exact(1 + 4 * channels, deadline)
            if reply is None:
                return None
            angles = decode_angles(reply, self.device_id, channels)
            # bytes beyond the last reply due mean this frame was too long
            if angles is not None and not (self._buffer and self._replies_after_this == 0):
                return angles
            # junk, a short or long frame, a foreign ID: resynchronise and ask again
            self.rejected_frames += 1
            self.transport.discard_input()
            self._buffer = b""
            if time.monotonic() >= deadline:
                return None
            self._write_command()

    # kinematics -----------------------------------------------------------------------
    def _state_from(self, angles_deg, t_ns: int):
        theta = np.radians(angles_deg)
        try:
            xy = self.arm.forward(theta) - WORKSPACE_CENTRE_XY_MM
        except KinematicsError:
            xy = self._position[:2]  # keep the last pose; the daemon sees a still handle
        else:
            self._theta = theta
        self._position = np.array([xy[0], xy[1], 0.0])
        return self._position.copy(), np.array([1.0, 0.0, 0.0, 0.0]), 0, self.calibrated

    def torques_for(self, force_n) -> np.ndarray:
        force = clamp_force(force_n, HAPLY_2DIY_LIMITS.max_force_n)
        try:
            torques = self.arm.torques(self._theta, force[:2])
        except (KinematicsError, np.linalg.LinAlgError):
            return np.zeros(2)
        return scale_to_limit(torques, TORQUE_LIMIT_NM)[0]


def create(argument: str | None = None, **options) -> Haply2DIYDevice:
    """`haply:PORT`. Options: read_timeout_s, device_id."""
    return Haply2DIYDevice(argument, read_timeout_s=float(options.get("read_timeout_s", 0.05)),
                           device_id=int(options.get("device_id", DEFAULT_DEVICE_ID)))
