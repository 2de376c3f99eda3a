"""An emulated WoodenHaptics-family arm: its Teensy firmware on a pty, its mechanism, a hand.

Written from the public sources only (nothing here comes from `sasprobe`):

Firmware (forsslund/woodenhaptics 6b9ad8a, firmware/woody_teensy_mini/woody_teensy_mini.ino):
`loop()` reads characters one by one until ']' (into a 127-byte buffer), counting
commas and noting where '[' was; no '[' → error 256, not two commas → 512, 127
characters without ']' → 128; then it drains what has already arrived and any
character there other than '\\n', '\\r' or NUL → 8 (a merged command). A command that
does not scan as `[%d,%d,%d]` → 1024. Errors are answered with the last counters and
change nothing. An accepted command restarts the 100 ms watchdog (which disables the
amplifiers and centres the PWM), enables the amplifiers, and sets each motor's PWM to
8191·(0.4·mA/6000 + 0.5) — 0 mA for a value beyond ±6000; the ESCON amplifiers are
assumed configured to the matching ±6 A over 10–90 % duty. The reply
`[model,c0,c1,c2,c3,c4,c5,error]` carries the encoder counters, zeroed at power-up and
by the calibration button.

Mechanism (forsslund/hfabapi cf00e97, hfab_math.h configurations and the comments on
`motor_and_body_aligned`; hfab_polhem.h link lengths; hfab_api.cpp home counts, which
are where the arm rests when its counters are zero): a motor turns its capstan, the
cable turns the body's drum the other way at capstan/drum diameter ratio, so a motor
whose axis points along the body's axis (right-hand rule) drives the body backwards.
Positive current turns a motor the way its encoder counts up. The room frame is the
one the tests work in: x right, y up, z toward the user, mm, origin at the published
workspace origin; the arm's base faces the user, its waist turns the arm to the user's
right as its angle grows.
"""

from __future__ import annotations

import math
import re
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

ESCON_MAX_MA = 6000
PWM_MAX = 8191  # 13-bit PWM
WATCHDOG_S = 0.1
BUFFER = 127
COMMAND = re.compile(rb"\[\s*([+-]?\d+),\s*([+-]?\d+),\s*([+-]?\d+)")  # sscanf "[%d,%d,%d]"
MOVE_EVERY_S = 0.002


@dataclass(frozen=True)
class Arm:
    """One model's mechanism, as the host library publishes it (lengths m, angles rad)."""

    code: int
    links: tuple  # serial: (Ln, Lb, Lc); four-bar: (L0, L1, L2, L3, L4, L5)
    four_bar: bool
    capstan: tuple
    drum: tuple
    motor_along_body: tuple
    counts_per_turn: tuple
    newton_metre_per_amp: tuple
    home_counts: (
        tuple  # the counts the host adds: the resting pose is where these are the encoder angles
    )
    origin: tuple  # workspace origin: toward the user, right, up

    def body_per_motor(self) -> np.ndarray:
        """Body angle per motor angle: the capstan ratio, negative where the motor drives it
        backwards."""
        ratio = np.asarray(self.capstan) / np.asarray(self.drum)
        return np.where(self.motor_along_body, -ratio, ratio)

    def home_bodies(self) -> np.ndarray:
        motor = (
            np.asarray(self.home_counts, dtype=float)
            / np.asarray(self.counts_per_turn)
            * 2.0
            * math.pi
        )
        return motor * self.body_per_motor()

    def tip_m(self, bodies) -> np.ndarray:
        """The tip in the room frame (right, up, toward the user), metres from the workspace
        origin."""
        waist, b, c = bodies
        if self.four_bar:
            reach, up = _four_bar(self.links, b, c)
        else:
            base, upper, fore = self.links
            reach = upper * math.sin(b) + fore * math.sin(c)
            up = base + upper * math.cos(b) - fore * math.cos(c)
        toward, right = reach * math.cos(waist), reach * math.sin(waist)
        o_toward, o_right, o_up = self.origin
        return np.array([right - o_right, up - o_up, toward - o_toward])


def _four_bar(links, b, c) -> tuple[float, float]:
    """Polhem's linkage in the plane of body B: (reach from the waist axis, height) of the tip.

    Body B (L1) pivots at +L0/2 on the base, the crank (L2) at −L0/2; the output link
    pivots at body B's end, its short arm (L4) joined to the crank's end by the coupler
    (L3), its long arm (L5) carrying the tip. The coupler's joint is the crossing of the
    circles around the crank end (L3) and body B's end (L4) that lies clockwise of the
    crank end as seen from body B's end (the assembly the arm is built in).
    """
    l0, l1, l2, l3, l4, l5 = links
    end_b = np.array([l0 / 2.0 + l1 * math.cos(b), l1 * math.sin(b)])
    end_crank = np.array([-l0 / 2.0 + l2 * math.cos(c), l2 * math.sin(c)])
    gap = end_crank - end_b
    d = float(np.hypot(*gap))
    along = (l4 * l4 - l3 * l3 + d * d) / (2.0 * d)
    across = math.sqrt(l4 * l4 - along * along)
    unit = gap / d
    joint = end_b + along * unit - across * np.array([-unit[1], unit[0]])  # clockwise side
    tip = end_b - l5 * (joint - end_b) / l4
    return float(tip[0]), float(tip[1])


ARMS = {
    1: Arm(
        1,
        (34e-3, 165e-3, 25e-3, 190e-3, 34e-3, 130.8e-3),
        True,
        (0.0288534, 0.0136981, 0.0137281),
        (0.175, 0.100, 0.100),
        (False, True, False),
        (4096, 4096, 4096),
        (0.0603, 0.0538, 0.0538),
        (8312, -10366, 19764),
        (0.2045, 0.0, 0.0325),
    ),
    2: Arm(
        2,
        (0.000, 0.138, 0.112),
        False,
        (0.013, 0.010, 0.010),
        (0.117, 0.077, 0.077),
        (True, False, True),
        (4000, 4000, 4000),
        (0.0234, 0.0234, 0.0234),
        (0, 7700, 0),
        (0.138, 0.000, -0.097),
    ),
    3: Arm(
        3,
        (0.080, 0.205, 0.245),
        False,
        (0.010, 0.010, 0.010),
        (0.160, 0.120, 0.120),
        (False, True, True),
        (2000, 2000, 2000),
        (0.0259, 0.0259, 0.0259),
        (0, 0, -6000),
        (0.220, 0.000, 0.080),
    ),
}


class WoodenHapticsEmulator(ArmUnderStylus, PtySerialDevice):
    """The board: `currents_ma` (what the amplifiers drive), `motor_force()` (N, room frame),
    `refused` (commands answered with an error; `refusals` their error bits), `stylus` and
    `hand` (mm, room frame)."""

    def __init__(
        self,
        directory,
        *,
        model: int = 3,
        reported_model: int | None = None,
        hand: MovableHand | None = None,
        gimbal_counts=(0, 0, 0),
        gimbal_error_bits: int = 0,
        name: str = "ttyWOODY0",
    ):
        self.arm = ARMS[model]
        self.reported_model = model if reported_model is None else reported_model
        self.gimbal_counts = tuple(gimbal_counts)
        self.gimbal_error_bits = gimbal_error_bits
        self.bodies = self.arm.home_bodies()
        home_mm = self.arm.tip_m(self.bodies) * 1000.0
        self.hand = hand or MovableHand()
        self.hand.place(home_mm)
        self.stylus = HeldStylus(home_mm, self.hand, mass_kg=0.12)
        self.refusals: list[int] = []  # the error bits of each refused command
        self.accepted = 0
        self.last_command_ma = None
        self.watchdog_trips = 0
        self._start_arm()
        super().__init__(directory, name)

    @property
    def refused(self) -> int:
        return len(self.refusals)

    # the firmware ---------------------------------------------------------------------
    def power_on(self) -> None:
        self.currents_ma = np.zeros(3)
        self.enabled = False
        self.counters = [0] * 6
        self._watchdog_at: float | None = None
        self._zero = self._motor_counts()  # setup(): quadEnc*.write(0) where the arm is

    def press_calibration_button(self) -> None:
        self._zero = self._motor_counts()

    def loop(self) -> None:
        error, start, text = self._await_message()
        if error:
            self._answer(error)
            return
        match = COMMAND.match(text[start:])
        if match is None:
            self._answer(1024)
            return
        self.accepted += 1
        self._watchdog_at = time.monotonic() + WATCHDOG_S
        self.enabled = True
        self.last_command_ma = asked = [int(v) for v in match.groups()]
        currents = [ma if -ESCON_MAX_MA <= ma <= ESCON_MAX_MA else 0 for ma in asked]
        duty = [int(PWM_MAX * (0.4 * ma / ESCON_MAX_MA + 0.5)) for ma in currents]
        self.stylus.advance(self._force)  # the old currents acted until now
        self.currents_ma = np.array([(d / PWM_MAX - 0.5) / 0.4 * ESCON_MAX_MA for d in duty])
        counts = self._motor_counts() - self._zero
        self.counters = [int(v) for v in counts] + list(self.gimbal_counts)
        self._answer(self.gimbal_error_bits, refused=False)
        self._refresh_force()  # the slow part after the answer, as the board's work is done

    def _await_message(self) -> tuple[int, int, bytes]:
        buf, start, commas = bytearray(), None, 0
        while len(buf) < BUFFER:
            c = self.wait_byte()
            buf.append(c)
            if c == ord("]"):
                if start is None:
                    return 256, 0, bytes(buf)
                if commas != 2:
                    return 512, 0, bytes(buf)
                while self.available():
                    if self.read() not in (ord("\n"), ord("\r"), 0):
                        return 8, 0, bytes(buf)
                return 0, start, bytes(buf)
            if c == ord("["):
                start = len(buf) - 1
            if c == ord(","):
                commas += 1
        return 128, 0, bytes(buf)

    def _answer(self, error: int, refused: bool = True) -> None:
        if refused:
            self.refusals.append(error)
        c = self.counters
        self.write(
            f"[{self.reported_model},{c[0]},{c[1]},{c[2]},{c[3]},{c[4]},{c[5]},{error}]\n".encode()
        )

    def tick(self) -> None:
        now = time.monotonic()
        if self._watchdog_at is not None and now >= self._watchdog_at:
            self._watchdog_at = None
            self.enabled = False  # wdCallback(): amplifiers off, PWM centred
            self.currents_ma = np.zeros(3)
            self.watchdog_trips += 1
            self._refresh_force()
        if now - self._moved_at >= MOVE_EVERY_S:
            self._move()

    # the mechanism --------------------------------------------------------------------
    def _follow(self, where_mm: np.ndarray) -> None:
        self.bodies = follow(lambda q: self.arm.tip_m(q) * 1000.0, self.bodies, where_mm)

    def _jacobian_now(self) -> np.ndarray:
        return numeric_jacobian(self.arm.tip_m, self.bodies)

    def _motor_counts(self) -> np.ndarray:
        motor = self.bodies / self.arm.body_per_motor()
        return np.round(motor / (2.0 * math.pi) * np.asarray(self.arm.counts_per_turn)).astype(int)

    def motor_force(self, currents_ma=None) -> np.ndarray:
        """The tip force (N, room frame) the motors make with these (or the present) currents."""
        currents = self.currents_ma if currents_ma is None else np.asarray(currents_ma, dtype=float)
        if currents_ma is None and not self.enabled:
            return np.zeros(3)
        motor_torque = currents / 1000.0 * np.asarray(self.arm.newton_metre_per_amp)
        body_torque = motor_torque / self.arm.body_per_motor()  # virtual work through the capstan
        return np.linalg.solve(self._jacobian.T, body_torque)  # τ = Jᵀ·F


def launch(*, directory=None, **options) -> Rig:
    """A WoodenHaptics board on a fresh pty, its arm resting in the home pose.

    Options: model (1 Polhem, 2 vintage PHANTOM, 3 Woody; default 3), reported_model,
    gimbal_counts, gimbal_error_bits. The hand holds the stylus; set `rig.hand.target`
    (mm, room frame = the device frame: x right, y up, z toward the user) to move it.
    """
    owned = tempfile.TemporaryDirectory(prefix="woody") if directory is None else None
    board = WoodenHapticsEmulator(owned.name if owned else directory, **options)
    return Rig(board, f"woodenhaptics:{board.path}", owned)
