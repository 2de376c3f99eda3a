"""An emulated Haply 2DIY: the M0 or M3 board firmware on a pty, the pantograph, a hand.

Written from the public sources only (nothing here comes from `sasprobe`):

Firmware (HaplyHaptics/Haply-Arduino-Firmware-Versions 6f75c27, Haply_M0_Firmware_V0_3
and Haply_M3_Firmware_V1_5): every ≥50 µs `loop()` takes one command byte if any
arrived: 0 reset (then the device address; every port forgets its owner), 1 setup
(address, motor port mask and one direction byte per motor, encoder mask and one
direction byte per encoder, a sensor count and pins, a PWM count and pins, then
`readBytes` of two float32 per encoder: start angle in degrees and resolution), 2
write (address, one float32 torque per motor the address owns, read with `readBytes`
— Arduino's 1 s timeout; then the reply: the address and one float32 angle per
encoder it owns). Other bytes are skipped; `read()` of an empty buffer gives −1.
No reply to reset or setup. An encoder counts from start angle·resolution/360 and
reports 360·count/resolution degrees; the M0 counts at half the quadrature rate and
halves the resolution to match, the M3 counts every edge. A direction byte of 1 (CCW)
swaps the encoder's pins. A torque is clamped to 0.123 N·m and becomes a PWM duty of
resolution·|τ|/0.123 (M0 1023, M3 4095) with the direction pin set by its sign and the
motor's direction byte; there is no watchdog.

The old board format (`firmware="v0.1"`): a header byte (type << 4 | port mask), the
device ID and float32 per port; setup (type 0) is answered with 5 bytes, type 1 with the
ID and an angle per port (what Haply-API-cpp v0.1.0 `Board::receive()` expects).

Mechanism (HaplyHAPI 1.0.1: l = 70 mm, L = 90 mm, d = 0 or 38 mm; which port drives
which link, directions, start angles and resolutions per generation): the pad lies on
the desk, link 1's motor at the origin, link 2's at (d, 0); x points to the user's left,
y toward the user, angles counter-clockwise seen from above. A motor's CW/CCW is seen
from its own face; gen 3's motors face up, gen 2's two coaxial motors face each other,
so port 1's (link 2's) CCW is clockwise seen from above. The handle is where the two
distal links meet on the user's side of the elbows. The room frame the tests use: x
right (−pad x), y up (the pad's height, fixed), z toward the user (pad y), mm, origin at
the centre we take for the workspace.
"""

from __future__ import annotations

import math
import struct
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from tests.emulators.physics import (
    ArmUnderStylus,
    HeldStylus,
    MovableHand,
    follow,
    numeric_jacobian,
)
from tests.emulators.pty_serial import PtySerialDevice, Rig

MAX_TORQUE = 0.123
MOVE_EVERY_S = 0.002


@dataclass(frozen=True)
class Pantograph:
    proximal: float
    distal: float
    spacing: float
    port_link: dict  # board port → the link it drives and reads
    faces_up: dict  # board port → True if the motor's own CCW is CCW seen from above
    start_deg: dict  # link → angle where the handle rests when the board is set up
    centre: tuple  # (pad x, pad y) of the workspace centre, m

    def handle(self, theta) -> np.ndarray:
        """(pad x, pad y), m, for link angles (rad)."""
        e1 = self.proximal * np.array([math.cos(theta[0]), math.sin(theta[0])])
        e2 = np.array([self.spacing, 0.0]) + self.proximal * np.array(
            [math.cos(theta[1]), math.sin(theta[1])]
        )
        mid, gap = (e1 + e2) / 2.0, e2 - e1
        half = float(np.hypot(*gap)) / 2.0
        rise = math.sqrt(self.distal**2 - half**2)
        normal = np.array([-gap[1], gap[0]]) / (2.0 * half)
        a, b = mid + rise * normal, mid - rise * normal
        return a if a[1] > b[1] else b  # on the user's side of the elbows

    def room_mm(self, theta) -> np.ndarray:
        x, y = self.handle(theta)
        return np.array([-(x - self.centre[0]), 0.0, y - self.centre[1]]) * 1000.0


PANTOGRAPHS = {
    "gen2": Pantograph(
        0.07, 0.09, 0.0, {1: 2, 2: 1}, {1: False, 2: True}, {1: 241.0, 2: -61.0}, (0.0, 0.080)
    ),
    "gen3": Pantograph(
        0.07, 0.09, 0.038, {1: 2, 2: 1}, {1: True, 2: True}, {1: 168.0, 2: 12.0}, (0.019, 0.090)
    ),
}


class HaplyBoard(ArmUnderStylus, PtySerialDevice):
    """The board: `torques` (N·m per port after the clamp), `motor_force()` (N, room frame),
    `stylus` and `hand` (mm, room frame)."""

    def __init__(
        self,
        directory,
        *,
        generation: str = "gen3",
        board: str = "M0",
        firmware: str = "current",
        hand: MovableHand | None = None,
        name: str = "ttyHAPLY0",
    ):
        self.mech = PANTOGRAPHS[generation]
        self.board = board
        self.firmware = firmware
        self.pwm_resolution = 1023 if board == "M0" else 4095
        self.theta = np.radians([self.mech.start_deg[1], self.mech.start_deg[2]])
        start = self.mech.room_mm(self.theta)
        self.hand = hand or MovableHand()
        self.hand.place(start)
        self.stylus = HeldStylus(
            start, self.hand, mass_kg=0.08, hand_stiffness_n_per_mm=0.3, planar_axis=1
        )
        self.writes = 0
        self._start_arm()
        super().__init__(directory, name)

    # the firmware ---------------------------------------------------------------------
    def power_on(self) -> None:
        self.owner = {}  # port → device address (the ports a setup gave to a host)
        # port → (direction, counts at setup, own angle at setup, resolution in use)
        self.encoders = {}
        self.motor_dirs = {}
        self.duty = {}  # port → signed duty in the motor's own sense
        self.address = None
        self.answer_due = False

    def loop(self) -> None:
        if self.firmware == "v0.1":
            self._old_format()
            return
        if not self.available():
            self.tick()
            self._fill(0.001)
        if self.available() > 0:
            command = self.read()
            if command == 0:
                self.address = self.read()
                self.owner = {}
            elif command == 1:
                self._setup()
            elif command == 2:
                self._write()
                self.answer_due = True
        if self.answer_due:
            self.answer_due = False
            angles = [
                self._angle(port)
                for port in sorted(self.encoders)
                if self.owner.get(port) == self.address
            ]
            self.write(bytes([self.address & 0xFF]) + struct.pack(f"<{len(angles)}f", *angles))
            self._refresh_force()  # the new torques (after the answer: the firmware's work is done)

    def _setup(self) -> None:
        self.owner = {}
        address = self.read()
        motor_ports = self._ports(self.read())
        motor_dirs = [self.read() for _ in motor_ports]
        encoder_ports = self._ports(self.read())
        encoder_dirs = [self.read() for _ in encoder_ports]
        for _ in range(max(self.read(), 0)):  # analog sensors: none on our pad
            self.read()
        for _ in range(max(self.read(), 0)):  # PWM pins
            self.read()
        params = struct.unpack(
            f"<{2 * len(encoder_ports)}f",
            self.read_bytes(8 * len(encoder_ports)).ljust(8 * len(encoder_ports), b"\0"),
        )
        self._move()
        for i, port in enumerate(encoder_ports):
            offset, resolution = params[2 * i], params[2 * i + 1]
            if self.board == "M0":
                resolution /= 2.0  # "encoder driver ... only detects on half the rate"
            self.encoders[port] = (
                1 if encoder_dirs[i] > 0 else -1,
                int(offset * resolution / 360.0),
                self._own_angle(port),
                resolution,
            )
            self.owner[port] = address
        for i, port in enumerate(motor_ports):
            self.motor_dirs[port] = motor_dirs[i]
            self.owner[port] = address
        self.address = address

    def _write(self) -> None:
        address = self.read()
        ports = [p for p in sorted(self.motor_dirs) if self.owner.get(p) == address]
        data = self.read_bytes(4 * len(ports)).ljust(4 * len(ports), b"\0")
        self.stylus.advance(self._force)  # the old torques acted until now
        for port, torque in zip(ports, struct.unpack(f"<{len(ports)}f", data)):
            ccw = self.motor_dirs[port] == 1
            duty = int(self.pwm_resolution * min(abs(torque), MAX_TORQUE) / MAX_TORQUE)
            self.duty[port] = (
                duty if (torque > 0) == ccw else -duty
            )  # signed in the motor's own CCW sense
            if torque == 0:
                self.duty[port] = 0
        self.address = address
        self.writes += 1

    def _ports(self, mask: int) -> list[int]:
        count = 2 if self.board == "M0" else 4
        return [p for p in range(1, count + 1) if mask >= 0 and mask & (1 << (p - 1))]

    def _angle(self, port: int) -> float:
        direction, start_count, start_own, resolution = self.encoders[port]
        turned = (self._own_angle(port) - start_own) / (2.0 * math.pi)
        count = start_count + int(round(direction * turned * resolution))
        return 360.0 * count / resolution

    def _old_format(self) -> None:
        header = self.wait_byte()
        kind, mask = header >> 4, header & 0x0F
        ports = bin(mask).count("1")
        if kind == 0:
            body = self.read_bytes(1 + 8 * ports)
            self.write(body[:1] + struct.pack("<f", 0.0))
        elif kind == 1:
            body = self.read_bytes(1 + 4 * ports)
            self.write(body[:1] + struct.pack(f"<{ports}f", *[0.0] * ports))

    def tick(self) -> None:
        if time.monotonic() - self._moved_at >= MOVE_EVERY_S:
            self._move()

    # the mechanism --------------------------------------------------------------------
    def _follow(self, where_mm: np.ndarray) -> None:
        self.theta = follow(lambda t: self.mech.room_mm(t)[[0, 2]], self.theta, where_mm[[0, 2]])

    def _jacobian_now(self) -> np.ndarray:
        return numeric_jacobian(self.mech.handle, self.theta)

    def _own_angle(self, port: int) -> float:
        link_angle = self.theta[self.mech.port_link[port] - 1]
        return link_angle if self.mech.faces_up[port] else -link_angle

    def port_torques(self) -> dict:
        """N·m per port in the motor's own CCW sense."""
        return {port: duty / self.pwm_resolution * MAX_TORQUE for port, duty in self.duty.items()}

    def motor_force(self) -> np.ndarray:
        """The handle force (N, room frame) the motors make now."""
        link_torque = np.zeros(2)
        for port, torque in self.port_torques().items():
            link_torque[self.mech.port_link[port] - 1] += (
                torque if self.mech.faces_up[port] else -torque
            )
        fx, fy = np.linalg.solve(self._jacobian.T, link_torque)  # τ = Jᵀ·F
        return np.array([-fx, 0.0, fy])


def launch(*, directory=None, generation: str = "gen3", **options) -> Rig:
    """A Haply board on a fresh pty with the handle resting in its start pose.

    Options: generation ("gen2", "gen3"), board ("M0", "M3"), firmware ("current",
    "v0.1"). Set `rig.hand.target` (mm, room frame = the device frame) to move the handle.
    """
    owned = tempfile.TemporaryDirectory(prefix="haply") if directory is None else None
    board = HaplyBoard(owned.name if owned else directory, generation=generation, **options)
    return Rig(board, f"haply:{generation}:{board.path}", owned)
