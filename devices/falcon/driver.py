"""The Novint Falcon as a HapticDevice: libnifalcon's way of running it, without blocking.

Opening follows libnifalcon on Linux (FalconCommLibUSB::open, FalconCLIBase): purge,
normal mode, then ask whether firmware is running (FalconFirmware::isFirmwareLoaded:
frames sent, a reply expected; up to ten kicks). If not, the image is uploaded
(`loader`), up to ten attempts with the USB reopened between them as FalconCLIBase
does, except that a loader that never answered its 100 probes is reported at once.

Running follows FalconFirmwareNovintSDK::runIOLoop: each frame is answered by one reply,
and no new frame goes out while earlier ones are unanswered. libnifalcon's free-running
loop keeps one frame in flight; ours is paced at 1 kHz and the FTDI may hold a reply
for its 1 ms latency timer, so we allow two, which keeps a command going out every
tick. Replies are read by the link's reader thread: `read()` only takes what has
arrived and `write_force()` only hands a frame over, neither waits on USB. Frames
unanswered for RESEND_AFTER_S are taken as lost and a fresh one is sent (libnifalcon
"kicks out another write"); a frame left unanswered for `reply_timeout_s` is a
DeviceFault (zero force), and the next reply ends the fault, so a stalled Falcon
recovers without a reconnect, and a burst of late replies leaves only the newest. The
Falcon's silence is timed from the first frame sent after its newest reply, never from
that reply: a host that sent nothing for a while (a busy machine, a late tick) finds
the Falcon's answers waiting, not a fault blamed on the device (the daemon's loop
zeroes a late tick itself).

Homing (FalconFirmware.h, FalconCLIBase::calibrateDevice): the homing-mode bit goes in
every frame, from open to close, since the firmware forgets its homing in a frame
without it. The LED is red until the Falcon reports all three axes homed, then green;
until then no force is sent.
"""

from __future__ import annotations

import collections
import logging
import os
import time
from pathlib import Path

import numpy as np
from sasprobe.devices.base import DeviceFault, DeviceInfo, DeviceOpenError, DeviceState
from sasprobe.devices.falcon import kinematics as K
from sasprobe.devices.falcon import loader
from sasprobe.devices.falcon import models as M
from sasprobe.devices.falcon import protocol as P
from sasprobe.devices.falcon.ftdi import FtdiLink
from sasprobe.devices.hardware import (
    HardwareDriver,
    VelocityFilter,
    clamp_force,
    factory_from_environment,
)
from sasprobe.devices.transports import UsbTransport

log = logging.getLogger("sasprobe.devices.falcon")

UPLOAD_ATTEMPTS = 10  # FalconCLIBase::loadFirmware
FIRMWARE_KICKS = 10  # FalconFirmware::isFirmwareLoaded: ten rounds of a hundred IO loops
FIRMWARE_KICK_WAIT_S = 0.02
MAX_IN_FLIGHT = 2
RESEND_AFTER_S = 0.005
REPLY_TIMEOUT_S = 0.02


class FalconDevice(HardwareDriver):
    """One Novint Falcon. `firmware` is the image uploaded when the device has none running."""

    def __init__(
        self,
        firmware: str | os.PathLike | None = None,
        *,
        usb_backend=None,
        reply_timeout_s: float = REPLY_TIMEOUT_S,
    ):
        self.firmware = Path(firmware) if firmware else None
        self.reply_timeout_ns = int(reply_timeout_s * 1e9)
        self._usb = UsbTransport(
            M.VENDOR_ID, M.PRODUCT_ID, M.EP_OUT, M.EP_IN, backend=usb_backend, label="Novint Falcon"
        )
        self._link = FtdiLink(self._usb)
        self._frames = P.FrameReader()
        self._velocity = VelocityFilter()
        self.force = np.zeros(3)  # the force last asked for, clamped
        self.motor = [0, 0, 0]  # the motor commands of the last frame sent
        self._homed = 0
        self._position_m = M.WORKSPACE_CENTRE_M.copy()
        self._jacobian: np.ndarray | None = None  # ∂p/∂θ1 there, once per reply
        self._state: DeviceState | None = None
        # send times of unanswered frames
        self._in_flight: collections.deque[int] = collections.deque()
        self._silent_since_ns: int | None = None  # the first frame sent since the newest reply
        self.firmware_uploads = 0
        self.upload_retries = 0
        self.resent_frames = 0

    # -- interface -------------------------------------------------------------------
    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(
            kind="falcon",
            model="Novint Falcon",
            limits=M.FALCON_LIMITS,
            details={
                "firmware": str(self.firmware) if self.firmware else None,
                "rejected_frames": self._frames.rejected,
                "homed_axes": bin(self._homed).count("1"),
                "firmware_uploads": self.firmware_uploads,
                "upload_retries": self.upload_retries,
                "resent_frames": self.resent_frames,
            },
        )

    @property
    def rejected_frames(self) -> int:
        return self._frames.rejected

    @property
    def calibrated(self) -> bool:
        return self._homed == P.ALL_HOMED

    def open(self) -> None:
        image = self._firmware_image()  # a missing file is the user's to fix, before touching USB
        self._homed = 0
        self._usb.open()
        try:
            self._link.purge()
            self._link.normal_mode()
            if not self._firmware_answers():
                if image is None:
                    raise DeviceOpenError(
                        "the Falcon has no firmware running: give the firmware file as falcon:PATH "
                        "(the image from the Falcon SDK/driver package, or libnifalcon's firmware/)"
                    )
                self._load(image)
                if not self._firmware_answers():
                    raise DeviceOpenError(
                        "the Falcon did not start after the firmware upload: "
                        "wrong firmware file? unplug it, plug it back in and try again"
                    )
        except DeviceFault as exc:
            self._shut()
            raise DeviceOpenError(f"the Falcon stopped answering while opening: {exc}") from None
        except BaseException:
            self._shut()
            raise
        self._velocity.reset()
        self.force = np.zeros(3)

    def close(self) -> None:
        self.force = np.zeros(3)
        self._link.stop()
        if self._usb.is_open:
            try:  # motors at zero, LEDs dark; the homing bit stays so the Falcon keeps its homing
                self._usb.write(P.encode_command([0, 0, 0], 0, homing=True))
            except DeviceFault:
                pass
        self._shut()

    def reconnect(self) -> None:
        if self._usb.is_open and self._link.error is None:
            # USB is fine but the firmware went quiet: never reload a running Falcon, kick it
            self._send_frame()
            raise DeviceFault(
                f"device still unavailable: the Falcon has not answered for "
                f"{self._silence_ns() / 1e6:.0f} ms "
                "although its USB link is up (unplug it and plug it back in if this lasts)"
            )
        super().reconnect()

    def read(self) -> DeviceState:
        try:
            if self._link.error is not None:
                raise DeviceFault(f"the Falcon's USB link failed: {self._link.error}")
            self._poll()
            silence_ns = self._silence_ns()
            if self._state is None or silence_ns > self.reply_timeout_ns:
                raise DeviceFault(f"the Falcon has not answered for {silence_ns / 1e6:.0f} ms")
        except DeviceFault:
            self.force = np.zeros(3)  # what any frame carries until it answers again
            raise
        return self._state

    def write_force(self, force_n) -> None:
        self.force = clamp_force(force_n, M.FALCON_LIMITS.max_force_n)
        if len(self._in_flight) < MAX_IN_FLIGHT:
            self._send_frame()
        elif time.monotonic_ns() - self._in_flight[0] > RESEND_AFTER_S * 1e9:
            self._in_flight.clear()  # taken as lost: send afresh
            self.resent_frames += 1
            self._send_frame()

    def motor_command(self, force_n) -> list[int]:
        """The motor commands rendering `force_n` at the current pose (zero until homed)."""
        if not self.calibrated or self._jacobian is None:
            return [0, 0, 0]
        return K.motor_commands(self._jacobian, clamp_force(force_n, M.FALCON_LIMITS.max_force_n))

    # -- frames ----------------------------------------------------------------------
    def _send_frame(self) -> None:
        self.motor = self.motor_command(self.force)
        leds = P.LED_GREEN if self.calibrated else P.LED_RED
        self._link.send(P.encode_command(self.motor, leds, homing=True))
        now = time.monotonic_ns()
        self._in_flight.append(now)
        if self._silent_since_ns is None:
            self._silent_since_ns = now

    def _silence_ns(self) -> int:
        """How long the Falcon has owed a reply (0 when it owes none)."""
        if self._silent_since_ns is None:
            return 0
        return time.monotonic_ns() - self._silent_since_ns

    def _poll(self) -> bool:
        """Take what the reader thread received; True when a new reply came."""
        data, arrived_ns = self._link.take()
        if not data:
            return False
        self._frames.feed(data)
        newest = None
        while (reply := self._frames.next_reply()) is not None:
            newest = reply
            if self._in_flight:
                self._in_flight.popleft()
        if newest is None:
            return False
        self._silent_since_ns = None
        self._homed = newest.homed
        self._position_m = self._locate(K.thigh_angles(newest.encoders))
        try:
            self._jacobian = K.jacobian(self._position_m)
        except K.KinematicsError:
            self._jacobian = None
        position_mm = K.to_device_mm(self._position_m)
        self._state = DeviceState(
            t_ns=arrived_ns,
            position_mm=position_mm,
            velocity_mm_s=self._velocity.update(arrived_ns, position_mm),
            buttons=newest.buttons,
            calibrated=self.calibrated,
        )
        return True

    def _locate(self, theta) -> np.ndarray:
        for guess in (self._position_m, None):  # homing moves the encoders' origin: start afresh
            try:
                return K.forward(theta, guess)
            except K.KinematicsError:
                continue
        if self.calibrated:
            raise DeviceFault("the Falcon's encoders match no reachable position")
        return self._position_m  # not homed yet: the counts are relative to power-on

    # -- firmware --------------------------------------------------------------------
    def _firmware_answers(self) -> bool:
        """Frames out, a reply back within ten kicks: firmware is running (link left running)."""
        self._frames.clear()
        self._state = None
        self._in_flight.clear()
        self._silent_since_ns = None
        self.force = np.zeros(3)
        self._link.start()
        for _ in range(FIRMWARE_KICKS):
            self._send_frame()
            deadline = time.monotonic() + FIRMWARE_KICK_WAIT_S
            while time.monotonic() < deadline:
                if self._link.error is not None:
                    raise DeviceFault(self._link.error)
                if self._poll():
                    return True
                time.sleep(0.001)
        self._link.stop()
        return False

    def _load(self, image: bytes) -> None:
        for attempt in range(1, UPLOAD_ATTEMPTS + 1):
            try:
                probes = loader.enter_firmware_mode(self._link)
                loader.upload(self._link, image)
            except loader.LoaderSilent as exc:
                raise DeviceOpenError(
                    f"{exc}: unplug the Falcon (USB and power), plug it back in and try again"
                ) from None
            except loader.UploadFailed as exc:
                self.upload_retries += 1
                log.info("Falcon firmware upload attempt %d failed: %s", attempt, exc)
                if attempt == UPLOAD_ATTEMPTS:
                    raise DeviceOpenError(
                        f"Falcon firmware upload failed {UPLOAD_ATTEMPTS} times ({exc}): "
                        "unplug the Falcon (USB and power), plug it back in and try again"
                    ) from None
                self._usb.close()  # FalconCLIBase closes and reopens between attempts
                self._usb.open()
                continue
            self.firmware_uploads += 1
            log.info(
                "Falcon firmware uploaded (%d bytes, loader answered probe %d)", len(image), probes
            )
            return

    def _firmware_image(self) -> bytes | None:
        if self.firmware is None:
            return None
        try:
            image = self.firmware.read_bytes()
        except FileNotFoundError:
            raise DeviceOpenError(f"Falcon firmware file not found: {self.firmware}") from None
        except OSError as exc:
            raise DeviceOpenError(
                f"cannot read the Falcon firmware file {self.firmware}: {exc.strerror}"
            ) from None
        if not image:
            raise DeviceOpenError(f"the Falcon firmware file {self.firmware} is empty")
        return image

    def _shut(self) -> None:
        self._link.stop()
        self._usb.close()
        self._frames.clear()
        self._state = None
        self._in_flight.clear()
        self._silent_since_ns = None


def create(argument: str | None = None, **options) -> FalconDevice:
    """`falcon[:FIRMWARE]`. Options: usb_backend (a pyusb backend; tests), reply_timeout_s.

    Without `usb_backend`, SASPROBE_USB_BACKEND=module:function names a factory of one
    (how the test suite points a daemon subprocess at its emulated Falcon).
    """
    backend = options.get("usb_backend") or factory_from_environment("SASPROBE_USB_BACKEND")
    return FalconDevice(
        argument or None,
        usb_backend=backend,
        reply_timeout_s=float(options.get("reply_timeout_s", REPLY_TIMEOUT_S)),
    )
