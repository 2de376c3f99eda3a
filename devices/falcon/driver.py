"""Novint Falcon over USB (FTDI bridge 0403:CB48) through pyusb.

Implemented from the public protocol description collected in the research notes (§3):

- **Firmware mode.** The Falcon boots into a loader; the host uploads a firmware image
  (a file the user supplies) over the FTDI link: purge; latency timer 16 ms; 9600 baud
  8N1, no flow control; RTS low, DTR low then high; send 0A 43 0D and expect
  00 0A 44 2C 0D; DTR low, baud divisor 0x15; send 'A' and expect 'A' back; then 128-byte
  blocks, each echoed back and compared. A failed echo retries the whole upload.
- **Normal mode.** Latency timer 1 ms, baud divisor 0x2, purge. Every 16-byte command
  produces one 16-byte reply; the host runs the control loop, so it must keep polling.
- **Frames.** '<', twelve nibble bytes (three signed 16-bit values, four nibbles each,
  least significant first; each byte is nibble + 0x41, 'A'..'P'), two flag nibbles, '>'.
  Out: motor commands, then LED bits (green 0x2, blue 0x4, red 0x8) and the homing bit
  0x01. Back: encoder counts, then a status byte whose low nibble is the buttons and whose
  bits 4-6 are the per-axis homed flags. Each payload byte carries one nibble, so we read
  flag bytes 13 and 14 as the low and high nibble of that one status byte.
- **Kinematics.** Encoder counts → thigh angles (320 slots × 4 counts per motor turn,
  14.25 mm shaft on a 110 mm drum, +35°) → delta forward kinematics (numeric); force →
  τ = Jᵀ·F, scaled by one factor at the torque limit, → signed motor counts within ±4096.

Calibration is the Falcon's homing: with the homing bit set the user moves the grip
through its full range until every axis has passed its index mark and reports homed.
Until then the LED is red and no force is sent; once homed it turns green.
"""

from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path

import numpy as np

from sasprobe.devices.base import DeviceFault, DeviceInfo, DeviceLimits, DeviceOpenError, DeviceState
from sasprobe.devices.ftdi import DIVISOR_9600, FtdiBridge
from sasprobe.devices.kinematics import DeltaArm, KinematicsError
from sasprobe.devices.support import HardwareDevice, VelocityFilter, clamp_force, factory_from_environment
from sasprobe.devices.transports import UsbTransport

log = logging.getLogger("sasprobe.devices.falcon")

VENDOR_ID, PRODUCT_ID = 0x0403, 0xCB48
EP_OUT, EP_IN = 0x02, 0x81

FRAME_SIZE = 16
FRAME_START, FRAME_END = ord("<"), ord(">")
NIBBLE_BASE = 0x41  # 'A'

LED_GREEN, LED_BLUE, LED_RED = 0x2, 0x4, 0x8
HOMING_MODE = 0x01
HOMED_SHIFT = 4  # status bits 4-6: axis 0-2 homed

MOTOR_LIMIT = 4096  # signed motor counts

# Loader handshake and timing.
LOADER_PROBE = b"\x0a\x43\x0d"
LOADER_REPLY = b"\x00\x0a\x44\x2c\x0d"
LOADER_HANDSHAKE = b"A"
FIRMWARE_BLOCK = 128
LOADER_DIVISOR = 0x15
NORMAL_DIVISOR = 0x2
UPLOAD_ATTEMPTS = 3

# Encoder → thigh angle: 320 slots × 4 counts per motor turn, 14.25 mm shaft, 110 mm drum.
COUNTS_PER_MOTOR_TURN = 320 * 4
SHAFT_TO_DRUM = 14.25 / 110.0
RAD_PER_COUNT = 2.0 * math.pi / COUNTS_PER_MOTOR_TURN * SHAFT_TO_DRUM  # ≈ 0.0364°
ANGLE_OFFSET = math.radians(35.0)

# The thigh torque that ±4096 motor counts stand for. Not published; chosen so that the
# centre of the workspace renders the advertised 8.9 N in every direction (our model).
TORQUE_LIMIT_NM = 0.47

FALCON_LIMITS = DeviceLimits(
    max_force_n=8.0,  # CHAI3D's Falcon record (H3D's spec sheet: > 8.9 N)
    continuous_force_n=4.0,  # not published: we budget half the peak
    max_stiffness_n_per_mm=3.0,  # CHAI3D: 3000 N/m
    max_damping_n_s_per_m=20.0,  # CHAI3D
    workspace_min_mm=(-40.0, -40.0, -40.0),  # CHAI3D: 0.04 m radius; our delta model's
    workspace_max_mm=(40.0, 40.0, 40.0),  # well-conditioned cube (kinematics.py)
    nominal_rate_hz=1000.0,
)


class FrameError(ValueError):
    """A reply that is not a valid Falcon frame."""


def encode_frame(values, flags: int) -> bytes:
    """Three signed 16-bit values and an 8-bit flag byte as one 16-byte frame."""
    out = bytearray(FRAME_SIZE)
    out[0], out[15] = FRAME_START, FRAME_END
    for i, v in enumerate(values):
        u = int(v) & 0xFFFF
        for k in range(4):
            out[1 + 4 * i + k] = NIBBLE_BASE + ((u >> (4 * k)) & 0xF)
    out[13] = NIBBLE_BASE + (flags & 0xF)
    out[14] = NIBBLE_BASE + ((flags >> 4) & 0xF)
    return bytes(out)


def decode_frame(frame: bytes) -> tuple[list[int], int]:
    """(three signed 16-bit values, flag byte) of one frame; FrameError if malformed."""
    if len(frame) != FRAME_SIZE:
        raise FrameError(f"frame of {len(frame)} bytes, expected {FRAME_SIZE}")
    if frame[0] != FRAME_START or frame[15] != FRAME_END:
        raise FrameError("frame not delimited by '<' ... '>'")
    nibbles = [b - NIBBLE_BASE for b in frame[1:15]]
    if any(n < 0 or n > 15 for n in nibbles):
        raise FrameError("byte outside the nibble range 'A'..'P'")
    values = []
    for i in range(3):
        u = sum(nibbles[4 * i + k] << (4 * k) for k in range(4))
        values.append(u - 0x10000 if u & 0x8000 else u)
    return values, nibbles[12] | (nibbles[13] << 4)


class FrameReader:
    """Finds frames in the byte stream; each discarded run of bytes counts as one rejection."""

    def __init__(self):
        self.buffer = b""
        self.rejected = 0

    def clear(self) -> None:
        self.buffer = b""

    def feed(self, data: bytes) -> None:
        self.buffer += data

    def next_frame(self) -> tuple[list[int], int] | None:
        while True:
            start = self.buffer.find(bytes([FRAME_START]))
            if start < 0:
                if self.buffer:
                    self.rejected += 1
                    self.buffer = b""
                return None
            if start > 0:  # junk before the frame start
                self.rejected += 1
                self.buffer = self.buffer[start:]
            if len(self.buffer) < FRAME_SIZE:
                return None
            candidate = self.buffer[:FRAME_SIZE]
            try:
                decoded = decode_frame(candidate)
            except FrameError:
                self.rejected += 1
                nxt = self.buffer.find(bytes([FRAME_START]), 1)
                self.buffer = self.buffer[nxt:] if nxt > 0 else b""
                continue
            self.buffer = self.buffer[FRAME_SIZE:]
            return decoded


def counts_to_angles(counts) -> np.ndarray:
    return ANGLE_OFFSET + np.asarray(counts, dtype=float) * RAD_PER_COUNT


def angles_to_counts(theta) -> np.ndarray:
    return np.round((np.asarray(theta, dtype=float) - ANGLE_OFFSET) / RAD_PER_COUNT).astype(int)


def torques_to_motor(torques_nm) -> list[int]:
    counts = np.round(np.asarray(torques_nm, dtype=float) / TORQUE_LIMIT_NM * MOTOR_LIMIT)
    return [int(c) for c in np.clip(counts, -MOTOR_LIMIT, MOTOR_LIMIT)]


def motor_to_torques(counts) -> np.ndarray:
    return np.asarray(counts, dtype=float) / MOTOR_LIMIT * TORQUE_LIMIT_NM


class FalconDevice(HardwareDevice):
    """One Novint Falcon. `firmware` is the image uploaded when the device has none running."""

    def __init__(self, firmware: str | os.PathLike | None = None, *, usb_backend=None,
                 read_timeout_s: float = 0.05, kinematics: DeltaArm | None = None):
        self.firmware = Path(firmware) if firmware else None
        self.read_timeout_s = read_timeout_s
        self.kinematics = kinematics or DeltaArm()
        self._usb = UsbTransport(VENDOR_ID, PRODUCT_ID, EP_OUT, EP_IN, backend=usb_backend, label="Novint Falcon")
        self._ftdi = FtdiBridge(self._usb)
        self._reader = FrameReader()
        self._velocity = VelocityFilter()
        self.force = np.zeros(3)  # the force last asked for, clamped; every frame renders it
        self.motor = [0, 0, 0]  # the motor counts of the last frame sent
        self._outstanding = 0  # frames sent whose replies have not been read
        self._homed = 0
        self._theta = counts_to_angles([0, 0, 0])
        self._position = np.zeros(3)
        self.firmware_uploads = 0
        self.upload_retries = 0

    # -- interface -------------------------------------------------------------------
    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(
            kind="falcon", model="Novint Falcon", limits=FALCON_LIMITS,
            details={"firmware": str(self.firmware) if self.firmware else None,
                     "rejected_frames": self.rejected_frames, "homed_axes": bin(self._homed).count("1"),
                     "firmware_uploads": self.firmware_uploads},
        )

    @property
    def rejected_frames(self) -> int:
        return self._reader.rejected

    @property
    def calibrated(self) -> bool:
        return self._homed == 0b111

    def open(self) -> None:
        image = self._firmware_image()  # a missing file is the user's to fix, before touching USB
        self._homed = 0  # until the Falcon says otherwise (it forgets its homing with its power)
        self._usb.open()
        try:
            self._enter_normal_mode()
            if not self._firmware_running():
                if image is None:
                    raise DeviceOpenError(
                        "the Falcon has no firmware running: give the firmware file as falcon:PATH "
                        "(the image from the Falcon SDK/driver package)")
                self._upload_with_retries(image)
                self._enter_normal_mode()
                if not self._firmware_running():
                    raise DeviceOpenError("the Falcon did not start after the firmware upload: "
                                          "wrong firmware file? unplug it, plug it back in and try again")
        except DeviceFault as exc:
            self._usb.close()
            raise DeviceOpenError(f"the Falcon stopped answering while opening: {exc}") from None
        except BaseException:
            self._usb.close()
            raise
        self._velocity.reset()
        self.force = np.zeros(3)

    def close(self) -> None:
        self.force = np.zeros(3)
        if self._usb.is_open:
            try:  # leave the motors at zero and the LEDs dark
                self._ftdi.write(encode_frame([0, 0, 0], 0))
            except DeviceFault:
                pass
        self._usb.close()
        self._outstanding = 0
        self._reader.clear()

    def read(self) -> DeviceState:
        if self._outstanding == 0:
            self._send()
        pending, self._outstanding = self._outstanding, 0
        for _ in range(pending):  # every reply owed; the newest describes the arm now
            counts, status = self._receive()
        now = time.monotonic_ns()
        self._homed = (status >> HOMED_SHIFT) & 0b111
        self._theta = counts_to_angles(counts)
        try:
            self._position = self.kinematics.forward(self._theta, guess=self._position)
        except KinematicsError as exc:
            if self.calibrated:
                raise DeviceFault(f"Falcon encoders out of the mechanism's reach: {exc}") from None
        return DeviceState(
            t_ns=now, position_mm=self._position.copy(),
            velocity_mm_s=self._velocity.update(now, self._position),
            buttons=status & 0xF, calibrated=self.calibrated,
        )

    def write_force(self, force_n) -> None:
        self.force = clamp_force(force_n, FALCON_LIMITS.max_force_n)
        self._send()

    def motor_command(self, force_n) -> list[int]:
        """Signed motor counts rendering `force_n` at the current pose (zero until homed)."""
        if not self.calibrated:
            return [0, 0, 0]
        force = clamp_force(force_n, FALCON_LIMITS.max_force_n)
        try:
            torques, _ = self.kinematics.torques(self._theta, force, TORQUE_LIMIT_NM, p=self._position)
        except (KinematicsError, np.linalg.LinAlgError):
            return [0, 0, 0]
        return torques_to_motor(torques)

    # -- frames ----------------------------------------------------------------------
    def _flags(self) -> int:
        return LED_GREEN if self.calibrated else (LED_RED | HOMING_MODE)

    def _send(self) -> None:
        self.motor = self.motor_command(self.force)
        self._ftdi.write(encode_frame(self.motor, self._flags()))
        self._outstanding += 1

    def _receive(self, timeout_s: float | None = None) -> tuple[list[int], int]:
        deadline = time.monotonic() + (self.read_timeout_s if timeout_s is None else timeout_s)
        while True:
            frame = self._reader.next_frame()
            if frame is not None:
                return frame
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DeviceFault("the Falcon did not answer within "
                                  f"{(self.read_timeout_s if timeout_s is None else timeout_s) * 1000:.0f} ms")
            self._reader.feed(self._ftdi.read_some(64, remaining))

    # -- firmware --------------------------------------------------------------------
    def _firmware_image(self) -> bytes | None:
        if self.firmware is None:
            return None
        try:
            image = self.firmware.read_bytes()
        except FileNotFoundError:
            raise DeviceOpenError(f"Falcon firmware file not found: {self.firmware}") from None
        except OSError as exc:
            raise DeviceOpenError(f"cannot read the Falcon firmware file {self.firmware}: {exc.strerror}") from None
        if not image:
            raise DeviceOpenError(f"the Falcon firmware file {self.firmware} is empty")
        return image

    def _enter_normal_mode(self) -> None:
        self._ftdi.set_latency_timer(1)
        self._ftdi.set_baud_divisor(NORMAL_DIVISOR)
        self._ftdi.purge()
        self._reader.clear()
        self._outstanding = 0

    def _firmware_running(self) -> bool:
        """Send a zero frame twice; running firmware answers with a valid frame."""
        self.force = np.zeros(3)
        for _ in range(2):
            self._send()
            try:
                self._receive(timeout_s=0.1)
                return True
            except DeviceFault:
                self._reader.clear()
            finally:
                self._outstanding = 0
        return False

    def _upload_with_retries(self, image: bytes) -> None:
        last = None
        for attempt in range(UPLOAD_ATTEMPTS):
            try:
                self.upload_firmware(image)
                self.firmware_uploads += 1
                return
            except _UploadError as exc:
                last = exc
                self.upload_retries += 1
                log.info("Falcon firmware upload attempt %d failed: %s", attempt + 1, exc)
        raise DeviceOpenError(f"Falcon firmware upload failed {UPLOAD_ATTEMPTS} times ({last}): "
                              "unplug the Falcon (USB and power), plug it back in and try again")

    def upload_firmware(self, image: bytes) -> None:
        """The loader sequence; raises _UploadError when an answer or an echo is wrong."""
        f = self._ftdi
        f.purge()
        f.set_latency_timer(16)
        f.set_baud_divisor(DIVISOR_9600)
        f.set_line_8n1()
        f.set_no_flow_control()
        f.set_rts(False)
        f.set_dtr(False)
        f.set_dtr(True)
        f.write(LOADER_PROBE)
        self._expect(LOADER_REPLY, "loader reply")
        f.set_dtr(False)
        f.set_baud_divisor(LOADER_DIVISOR)
        f.write(LOADER_HANDSHAKE)
        self._expect(LOADER_HANDSHAKE, "loader handshake")
        for offset in range(0, len(image), FIRMWARE_BLOCK):
            block = image[offset:offset + FIRMWARE_BLOCK]
            f.write(block)
            self._expect(block, f"echo of block {offset // FIRMWARE_BLOCK}")

    def _expect(self, wanted: bytes, what: str) -> None:
        try:
            got = self._ftdi.read_exact(len(wanted), 0.5)
        except DeviceFault as exc:
            raise _UploadError(f"no {what}: {exc}") from None
        if got != wanted:
            raise _UploadError(f"wrong {what}")


class _UploadError(Exception):
    pass


def create(argument: str | None = None, **options) -> FalconDevice:
    """`falcon[:FIRMWARE]`. Options: usb_backend (a pyusb backend; tests), read_timeout_s.

    Without `usb_backend`, SASPROBE_USB_BACKEND=module:function names a factory of one
    (how the test suite points a daemon subprocess at its emulated Falcon).
    """
    backend = options.get("usb_backend") or factory_from_environment("SASPROBE_USB_BACKEND")
    return FalconDevice(argument or None, usb_backend=backend,
                        read_timeout_s=float(options.get("read_timeout_s", 0.05)))
