"""The emulated Novint Falcon's device side: its FTDI bridge, loader and firmware, and
the grip on a spring hand. From libnifalcon only (github.com/libnifalcon/libnifalcon,
commit f7c727a); nothing here comes from sasprobe:
- the FTDI bridge (FalconCommLibUSB.cpp): vendor requests purge 0, modem control 1,
  flow 2, baud divisor 3, line 4, latency timer 9; every IN packet starts with two
  status bytes, and the chip sends a packet when 62 data bytes wait or its latency
  timer runs out (then possibly with no data);
- the loader (FalconCommLibUSB::setFirmwareMode): after DTR goes high, at 9600 baud
  (divisor 0x4138) it answers 0A 43 0D with 0A 44 2C 0D as a Linux host sees it (00 0A
  44 2C 0D on macOS), after `probes_ignored` probes it sleeps through; at divisor 0x15
  'A' is echoed, then every image byte; the firmware starts when the host switches to
  normal mode (divisor 0x2) with the whole image loaded (when it starts is our guess);
- the firmware (FalconFirmwareNovintSDK.h/.cpp): one 16-byte reply per 16-byte command,
  '<' … '>', bytes 'A'..'P' in commands; motors (signed 16-bit), LEDs (green 2, blue 4,
  red 8), homing mode 1; replies with encoders and byte 13 = 'A' + buttons + homed axes
  << 4. A command without the homing bit makes it forget its homing (FalconFirmware.h:
  "must be set in each input packet ... to stay homed"); in homing mode an axis homes
  when its thigh passes its index mark, where the count becomes 0 (35°, getTheta).
  A command it cannot parse, or a motor value beyond the documented ±4096, is refused.
- the mechanism: `falcon_mechanism`; the grip is held by a spring hand (`physics`).
"""

from __future__ import annotations

import collections
import errno
import math
import threading
import time
from dataclasses import dataclass

import numpy as np
import usb.core

from tests.emulators import falcon_mechanism as mech
from tests.emulators.physics import HeldStylus

MODEM_STATUS = b"\x01\x60"  # CTS/DSR idle, transmitter empty
FULL_PACKET = 62
PROBE, LINUX_REPLY, MACOS_REPLY = b"\x0a\x43\x0d", b"\x0a\x44\x2c\x0d", b"\x00\x0a\x44\x2c\x0d"
DIVISOR_9600, DIVISOR_LOADER, DIVISOR_NORMAL = 0x4138, 0x15, 0x2
LED_RED, HOMING = 0x8, 0x1
COMMAND_LIMIT = 4096


@dataclass
class Sample:
    """One command as the motors carried it out."""

    t_ns: int
    motor: tuple
    force_n: np.ndarray  # on the grip, device-frame axes
    grip_mm: np.ndarray  # where the grip was (device frame)


class FalconHardware:
    def __init__(
        self,
        firmware: bytes,
        *,
        hand=None,
        start_mm=(0.0, 0.0, 0.0),
        hand_stiffness_n_per_mm=0.5,
        probes_ignored: int = 2,
        macos: bool = False,
        loader_silent: bool = False,
        corrupt_echo_attempts=(),
    ):
        self.expected_firmware = bytes(firmware)
        self.hand, self.start_mm, self.hand_stiffness = hand, start_mm, hand_stiffness_n_per_mm
        self.probes_ignored, self.macos, self.loader_silent = probes_ignored, macos, loader_silent
        self.corrupt_echo_attempts = set(corrupt_echo_attempts)
        self.lock = threading.RLock()
        self.plugged, self.generation = True, 0
        self.buttons = 0
        self.inject_before_reply: list[bytes] = []  # raw bytes put ahead of the next reply
        self.samples: collections.deque[Sample] = collections.deque(maxlen=20000)
        self.refused = 0  # commands the firmware could not take
        self.homing_losses = 0
        self.upload_attempts = 0
        self.probes_seen = 0
        self.replies = 0
        self.host_reads = 0  # IN transfers the host began
        self.reply_read = 0  # the one that took the last byte of the newest reply
        self.silent_until = 0.0  # a stall: commands wait until then
        self.hung = False  # stopped answering for good
        self._power_on()

    # -- power and cable --------------------------------------------------------------
    def _power_on(self) -> None:
        self.running = False
        self.loader = "idle"
        self.loaded = bytearray()
        self.latency_ms, self.divisor, self.dtr = 16, DIVISOR_9600, False
        self.out = bytearray()  # chip → host
        self.pending = bytearray()  # host → firmware, not yet taken
        self.leds, self.homing, self.homed = 0, False, [False, False, False]
        self.motor = (0, 0, 0)
        self.stylus = HeldStylus(
            self.start_mm, hand=self.hand, mass_kg=0.15, hand_stiffness_n_per_mm=self.hand_stiffness
        )
        self.offset_counts = self._absolute_counts()  # relative encoders: 0 where it was powered on
        self._last_angles = mech.thigh_angles(self.grip_m)

    def unplug(self) -> None:
        with self.lock:
            self.plugged = False
            self.generation += 1

    def replug(self) -> None:
        with self.lock:
            self._power_on()
            self.plugged = True

    def stall(self, seconds: float = math.inf) -> None:
        """The firmware stops answering for a while (without `seconds`, until `answer_again()`);
        commands sent meanwhile wait."""
        self.silent_until = time.monotonic() + seconds

    def answer_again(self) -> None:
        self.silent_until = 0.0

    def replies_taken(self) -> bool:
        """Every command is answered and the host has taken every reply, and came back for more
        since (so whatever reads its transfers holds them)."""
        with self.lock:
            return not self.pending and not self.out and self.host_reads > self.reply_read

    # -- mechanism --------------------------------------------------------------------
    @property
    def grip_m(self) -> np.ndarray:
        return mech.mechanism_m(self.stylus.position)

    def _absolute_counts(self) -> np.ndarray:
        return (mech.thigh_angles(self.grip_m) - mech.INDEX_ANGLE) / mech.RAD_PER_COUNT

    def check(self, generation: int) -> None:
        """USBError(ENODEV) for a handle opened before the cable was pulled, or none plugged."""
        if not self.plugged or generation != self.generation:
            raise usb.core.USBError("No such device", errno=errno.ENODEV)

    # -- FTDI control requests --------------------------------------------------------
    def control(self, generation: int, request: int, value: int, index: int) -> None:
        with self.lock:
            self.check(generation)
            if request == 0 and value == 1:  # libftdi's "rx": what waits for the host
                self.out.clear()
            elif request == 0 and value == 2:
                self.pending.clear()
            elif request == 9:
                self.latency_ms = value & 0xFF
            elif request == 3:
                self.divisor = value | (index << 16)
                if self.divisor == DIVISOR_NORMAL and self.loader == "loading":
                    self.running = self.loaded == self.expected_firmware
                    self.loader = "idle"
                elif self.divisor == DIVISOR_LOADER and self.loader == "probed":
                    self.loader = "handshake"
            elif request == 1 and value & 0x0100:
                rising = bool(value & 0x01) and not self.dtr
                self.dtr = bool(value & 0x01)
                if rising and not self.running:  # DTR resets the microcontroller into its loader
                    self.loader, self.probes_seen = "reset", 0
                    self.loaded.clear()

    # -- bytes from the host ----------------------------------------------------------
    def host_write(self, generation: int, data: bytes) -> None:
        with self.lock:
            self.check(generation)
            if not self.running:
                self._loader_bytes(bytes(data))
                return
            self.pending += data
            self._serve()

    def _loader_bytes(self, data: bytes) -> None:
        if self.loader == "reset" and self.divisor == DIVISOR_9600 and data == PROBE:
            self.probes_seen += 1
            if not self.loader_silent and self.probes_seen > self.probes_ignored:
                self.out += MACOS_REPLY if self.macos else LINUX_REPLY
                self.loader = "probed"
        elif self.loader == "handshake" and self.divisor == DIVISOR_LOADER and data == b"A":
            self.out += data
            self.loader = "loading"
            self.upload_attempts += 1
        elif self.loader == "loading" and self.divisor == DIVISOR_LOADER:
            echo = bytearray(data)
            if self.upload_attempts in self.corrupt_echo_attempts and not self.loaded:
                echo[0] ^= 0xFF  # a flaky link: one bad byte in the first echo
            self.loaded += data
            self.out += echo
        # anything else (frames sent to the loader, a wrong rate) is lost on a loader

    def _serve(self) -> None:
        """Answer every complete command, unless stalled or hung."""
        if self.hung or time.monotonic() < self.silent_until:
            return
        while len(self.pending) >= 16:
            command = bytes(self.pending[:16])
            del self.pending[:16]
            self._command(command)

    def _command(self, frame: bytes) -> None:
        nibbles = [b - 0x41 for b in frame[1:15]]
        if (
            self.divisor != DIVISOR_NORMAL
            or frame[0] != 0x3C
            or frame[15] != 0x3E
            or any(not 0 <= n <= 15 for n in nibbles)
        ):
            self.refused += 1
            return
        motor = []
        for i in range(3):
            u = sum(nibbles[4 * i + k] << (4 * k) for k in range(4))
            motor.append(u - 0x10000 if u >= 0x8000 else u)
        if any(abs(m) > COMMAND_LIMIT for m in motor):
            self.refused += 1
            motor = [0, 0, 0]
        flags = nibbles[12]
        self.leds, self.homing, self.motor = flags & 0xE, bool(flags & HOMING), tuple(motor)
        if not self.homing and any(self.homed):
            self.homing_losses += 1
            self.homed = [False, False, False]
        force = mech.grip_force(self.grip_m, self.motor)
        self.samples.append(
            Sample(time.monotonic_ns(), self.motor, force, self.stylus.position.copy())
        )
        self.stylus.advance(force)
        self._reply()

    def _reply(self) -> None:
        angles = mech.thigh_angles(self.grip_m)
        if self.homing:
            for i in range(3):
                crossed = (angles[i] - mech.INDEX_ANGLE) * (
                    self._last_angles[i] - mech.INDEX_ANGLE
                ) <= 0
                if not self.homed[i] and crossed:
                    self.homed[i], self.offset_counts[i] = True, 0.0
        self._last_angles = angles
        counts = np.round(
            (angles - mech.INDEX_ANGLE) / mech.RAD_PER_COUNT - self.offset_counts
        ).astype(int)
        status = (self.buttons & 0xF) | sum(1 << (4 + i) for i in range(3) if self.homed[i])
        body = [((int(c) & 0xFFFF) >> (4 * k)) & 0xF for c in counts for k in range(4)] + [
            status,
            0,
        ]
        for junk in self.inject_before_reply:
            self.out += junk
        self.inject_before_reply = []
        self.out += bytes([0x3C, *(b + 0x41 for b in body), 0x3E])
        self.replies += 1

    # -- bytes to the host ------------------------------------------------------------
    def host_read(self, generation: int, size: int, timeout_ms: int) -> bytes:
        """One IN packet: at once when a full one waits, else when the latency timer runs out."""
        deadline = time.monotonic() + min(max(self.latency_ms, 1), max(timeout_ms, 1)) / 1000.0
        with self.lock:
            self.host_reads += 1
            number = self.host_reads
        while True:
            with self.lock:
                self.check(generation)
                self._serve()  # a stall that ended answers what waited
                if len(self.out) >= FULL_PACKET or time.monotonic() >= deadline:
                    n = min(size - len(MODEM_STATUS), len(self.out))
                    data = bytes(self.out[:n])
                    del self.out[:n]
                    if data and not self.out:
                        self.reply_read = number
                    return MODEM_STATUS + data
            time.sleep(min(0.0005, max(deadline - time.monotonic(), 0.0)))


class Hand:
    """Where the user holds the grip (device frame, mm): `target`, or, while the LED is red
    and `homes` is set, the homing gesture libnifalcon asks for (FalconCLIBase::
    calibrateDevice: "Move control all the way out then push straight all the way in"):
    out to +35 mm and back once a second."""

    def __init__(self, target=(0.0, 0.0, 0.0), homes: bool = True):
        self.target, self.homes = tuple(target), homes
        self.hardware: FalconHardware | None = None

    def __call__(self, t: float):
        if self.homes and self.hardware is not None and self.hardware.leds & LED_RED:
            return (0.0, 0.0, 35.0 * math.sin(math.pi * t) ** 2)
        return self.target
