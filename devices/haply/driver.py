"""The Haply 2DIY as a HapticDevice: the M0/M3 board protocol and Haply's pantograph.

Opening follows Haply's libraries: a reset, the setup message (the board answers
nothing), then zero-torque writes every 100 ms until the board answers one. A board
that answers the reset or the setup is not running the M0/M3 firmware (the old v0.1
header format answers a setup); one that answers a write with its ID alone has not
taken the setup, which is then sent again. The session is the shared serial-arm
exchange (`serial_arm.py`).

Calibration: the setup message declares the handle's pose at that moment to be the
generation's start pose (the encoders' offsets), so the handle must rest in its start
pose when sasprobe opens the board. `reconnect()` after a lost port sets the board up
again only if it has forgotten its setup (a board that answers a write in full keeps
counting from the first one).
"""

from __future__ import annotations

import logging
import time

import numpy as np
from sasprobe.devices.base import DeviceInfo, DeviceOpenError
from sasprobe.devices.haply import kinematics, protocol
from sasprobe.devices.haply.models import DEFAULT_GENERATION, GENERATIONS
from sasprobe.devices.kinematics import KinematicsError, scale_to_limit
from sasprobe.devices.serial_arm import (
    JUNK_PROBES,
    PROBE_INTERVAL_S,
    BadFrame,
    SerialArm,
    timing_options,
)

log = logging.getLogger("sasprobe.devices.haply")

SETUP_SILENCE_S = 0.02  # how long the board must stay silent after reset and setup
MAX_STEP_DEG = 45.0  # more than this between two replies (1 ms apart) is a broken frame, not motion
SETUP_ATTEMPTS = 3


class Haply2DIYDevice(SerialArm):
    scheme = "haply"

    def __init__(
        self,
        port: str | None,
        *,
        generation: str = DEFAULT_GENERATION,
        device_id: int = protocol.DEFAULT_DEVICE_ID,
        **timing,
    ):
        if generation not in GENERATIONS:
            raise DeviceOpenError(
                f"unknown Haply 2DIY generation '{generation}' (known: {', '.join(GENERATIONS)})"
            )
        super().__init__(port, **timing)
        self.generation = GENERATIONS[generation]
        self.device_id = device_id
        self.set_up = False
        self.setups_sent = 0
        # per port, as the board reports them
        self.board_angles_deg: tuple[float, ...] | None = None
        self.theta = np.radians(
            [
                self.generation.port_for(1).start_angle_deg,
                self.generation.port_for(2).start_angle_deg,
            ]
        )
        self._position = np.zeros(3)

    @property
    def _max_force_n(self) -> float:
        return self.generation.limits.max_force_n

    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(
            kind=self.scheme,
            model=self.generation.name,
            limits=self.generation.limits,
            serial=self.port,
            details={
                "device_id": self.device_id,
                "planar": True,
                "setups_sent": self.setups_sent,
                "angles_deg": list(self.board_angles_deg or ()),
                "replies": self.replies,
                "rejected_frames": self.rejected_frames,
                "stale_replies": self.stale_replies,
                "resyncs": self.resyncs,
            },
        )

    # wire -----------------------------------------------------------------------------
    def _zero_command(self) -> bytes:
        return protocol.encode_write(self.device_id, [0.0, 0.0])

    def _command(self) -> bytes:
        return protocol.encode_write(self.device_id, self.port_torques(self.force))

    def _renderable(self, force_n):
        force = np.array(force_n, dtype=float).reshape(-1)
        if force.shape == (3,):
            force[1] = 0.0  # the pad is flat: nothing pushes up or down
        return force

    def _zero_may_overlap(self) -> bool:
        # fixed-size frames cannot merge, and the board has no watchdog: always send zero
        return True

    def _split(self, inbox: bytes):
        size = protocol.reply_size(len(self.generation.ports))
        if len(inbox) < size:
            return None, inbox
        reply = protocol.decode_angles(inbox[:size], self.device_id, len(self.generation.ports))
        if (
            self.board_angles_deg is not None
            and max(abs(a - b) for a, b in zip(reply.degrees, self.board_angles_deg)) > MAX_STEP_DEG
        ):
            raise BadFrame(
                f"a reply whose angles jumped from {self.board_angles_deg} to {reply.degrees}"
            )
        return reply, inbox[size:]

    def _take(self, reply: protocol.Angles) -> None:
        self.board_angles_deg = reply.degrees
        by_port = dict(zip((p.port for p in self.generation.ports), reply.degrees))
        theta = np.radians(
            [by_port[self.generation.port_for(1).port], by_port[self.generation.port_for(2).port]]
        )
        try:
            xy = kinematics.handle(self.generation, theta)
        except KinematicsError:
            return  # the links cannot meet: a glitch; keep the last pose
        self.theta = theta
        self._position = kinematics.to_device_mm(self.generation, xy)

    def _state(self, t_ns: int):
        return self._position.copy(), np.array([1.0, 0.0, 0.0, 0.0]), 0

    def port_torques(self, force_n) -> list[float]:
        """Torques (N·m) per board port for a device-frame force, scaled by one factor to the
        board's clamp so the force keeps its direction."""
        try:
            links = kinematics.link_torques(self.generation, self.theta, force_n)
        except (KinematicsError, np.linalg.LinAlgError):
            return [0.0, 0.0]
        links, _ = scale_to_limit(links, protocol.MAX_TORQUE_NM)
        return [float(links[p.link - 1]) for p in self.generation.ports]

    # handshake ------------------------------------------------------------------------
    def _handshake(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        self.transport.discard_input()
        if self.set_up and self._answers_in_full(deadline):
            log.info(
                "%s: the board kept its setup; its encoders still count from the first one",
                self.port,
            )
            return
        self.board_angles_deg = None
        for _attempt in range(SETUP_ATTEMPTS):
            self._send_setup()
            if self._answers_in_full(deadline):
                self.set_up = True
                return
            log.warning(
                "%s: the board answered without its encoders: setting it up again", self.port
            )
        raise DeviceOpenError(
            f"the board on {self.port} does not take the 2DIY setup "
            f"({SETUP_ATTEMPTS} tries): is its encoder/motor wiring on ports 1 and 2?"
        )

    def _send_setup(self) -> None:
        self.transport.write(protocol.encode_reset())
        self.transport.write(protocol.encode_setup(self.device_id, self.generation.ports))
        self.setups_sent += 1
        if self.transport.read(4096, SETUP_SILENCE_S):
            raise DeviceOpenError(
                f"the board on {self.port} answered the reset/setup messages, which the Haply "
                "M0/M3 firmware never does: it runs another firmware (the old v0.1 header "
                "format?); flash Haply_M0_Firmware_V0_3 or Haply_M3_Firmware_V1_5"
            )

    def _answers_in_full(self, deadline: float) -> bool:
        """Probe with zero torques until the board answers: True for a full reply, False for
        its ID alone (no setup); DeviceOpenError for silence or foreign bytes."""
        size = protocol.reply_size(len(self.generation.ports))
        junk = b""
        for _probe in range(int(self.handshake_timeout_s / PROBE_INTERVAL_S) + 1):
            if time.monotonic() >= deadline:
                break
            self.transport.write(self._zero_command())
            answer = self._answer(min(deadline, time.monotonic() + PROBE_INTERVAL_S))
            if not answer:
                continue
            if len(answer) < size and set(answer) == {self.device_id}:
                return False
            frames = [answer[i : i + size] for i in range(0, len(answer), size)]
            try:
                replies = [self._split(frame)[0] for frame in frames]
            except BadFrame:
                replies = []
            # late answers to earlier probes, then ours
            if replies and all(r is not None for r in replies):
                self.board_angles_deg = None
                self._take(replies[-1])
                self._sent_at = None
                return True
            junk = (junk + answer)[-64:]
            if _probe + 1 >= JUNK_PROBES:
                break
        if junk:
            raise DeviceOpenError(
                f"{self.port} answered, but not as a Haply M0/M3 board (device ID "
                f"{self.device_id}, {size}-byte replies): got {junk.hex(' ')}"
            )
        raise DeviceOpenError(
            f"{self.port} opened, but the board never answered within "
            f"{self.handshake_timeout_s:g} s (is it a Haply M0/M3 board with its firmware?)"
        )

    def _answer(self, deadline: float) -> bytes:
        """What arrives until `deadline`, or until SETUP_SILENCE_S of quiet after the first byte."""
        data = b""
        while True:
            wait = deadline - time.monotonic() if not data else SETUP_SILENCE_S
            if wait <= 0:
                return data
            chunk = self.transport.read(4096, wait)
            if not chunk:
                return data
            data += chunk


def create(argument: str | None = None, **options) -> Haply2DIYDevice:
    """`haply:PORT` (generation 3) or `haply:gen2:PORT` / `haply:gen3:PORT`.

    Options: device_id, rate_hz, reply_timeout_s, stale_after_s, handshake_timeout_s.
    """
    generation = DEFAULT_GENERATION
    if argument:
        head, sep, rest = argument.partition(":")
        if sep and head.lower() in GENERATIONS:
            generation, argument = head.lower(), rest
    device_id = int(options.get("device_id") or protocol.DEFAULT_DEVICE_ID)
    return Haply2DIYDevice(
        argument, generation=generation, device_id=device_id, **timing_options(options)
    )
