"""PHANTOM Omni / Touch (and other HDAPI arms) through the vendor's HD library, as a HapticDevice.

The arms' own wire protocols are not public, so this driver follows the HDAPI flow of
the SDK's examples (danepowell/openhaptics, commit 2ce9a48,
usr/share/3DTouch/examples/HD/console/): hdInitDevice → read the nominal limits and the
calibration styles → (encoder reset, see below) → hdScheduleAsynchronous(servo
callback) → hdEnable(HD_FORCE_OUTPUT) → hdStartScheduler (AnchoredSpringForce.c). The
callback runs in the library's 1 kHz servo thread: inside hdBeginFrame/hdEndFrame it
reads position, velocity, transform and buttons, checks the calibration and writes the
latest force.

Calibration (Calibration.c): the style is AUTO over INKWELL over ENCODER_RESET among
those the device supports. AUTO and INKWELL are updated from the servo loop whenever
hdCheckCalibration says HD_CALIBRATION_NEEDS_UPDATE (an inkwell arm needs its stylus in
the inkwell first: NEEDS_MANUAL_INPUT keeps `calibrated=False`, no force). An encoder
reset zeroes the encoders where the arm is, so it is done once, before the scheduler
starts, and only when the user says the arm is at its reset position (all links
orthogonal): `openhaptics[:NAME]:reset-encoders`. Without it an uncalibrated
encoder-reset arm is refused at open; a reconnect never resets again.

Errors (AnchoredSpringForce.c, ErrorHandling.c): after each frame the error stack is
drained. A force error (hduIsForceError's codes, see hdapi; and, our choice for safety,
HD_DEVICE_FAULT) stops force output; the callback goes on. The examples give force back
only once the user has acted: ErrorHandling.c (danepowell/openhaptics, commit 2ce9a48,
examples/HD/console/ErrorHandling/ErrorHandling.c l. 279-303) allows contact again once
the device is on the free side of the surface, whichever way it got there,
AnchoredSpringForce.c (l. 196-202, 227-233) after a new button press. The driver sits
below the daemon and sees no surface, but the daemon's commands say where the free side
is: a force computed from a valid, on-time reading of the stylus that is exactly zero
says "no contact here". So force comes back after FREE_COMMANDS such zeros in a row,
whichever way the stylus left the contact. Zeros that say nothing of the contact never
count and start the count again: the watchdog's (`zero_force_now`) and the daemon's
withheld force (`withhold_force`: a failed or late read, the first tick of a ramp); so
does a command of any force (still in contact). A new button press re-arms at once.
Either way the force then ramps in: scaled from 0 to 1 over RESUME_RAMP_FRAMES servo
frames, counted from the first frame that has force to render, so a command that arrives
after a stall still comes in gradually, never as a step.

A scheduler error (communication, timer) is reported by the next `read()` as a
DeviceFault. The callback that sees it disables force output (hdDisable(HD_FORCE_OUTPUT):
"all motors are turned on or off", Reference Table A-10) before it returns
HD_CALLBACK_DONE: a second frame in the same tick is refused (HD_ONE_FRAME_LIMIT), and
nothing may depend on the library calling again. Other errors are counted and logged.
"""

from __future__ import annotations

import ctypes
import logging
import threading
import time

import numpy as np
from sasprobe.devices.base import (
    PHANTOM_OMNI_LIMITS,
    DeviceFault,
    DeviceInfo,
    DeviceLimits,
    DeviceOpenError,
    DeviceState,
)
from sasprobe.devices.hardware import HardwareDriver, clamp_force
from sasprobe.devices.kinematics import quaternion_from_matrix
from sasprobe.devices.openhaptics import hdapi
from sasprobe.devices.openhaptics.hdapi import error_name

log = logging.getLogger("sasprobe.devices.openhaptics")

RESET_ENCODERS = "reset-encoders"
# the daemon's zero commands in a row from valid, on-time reads: out of contact
FREE_COMMANDS = 3
# after a force error, force ramps back in over 0.5 s of the 1 kHz servo loop
RESUME_RAMP_FRAMES = 500
MAX_ERRORS_PER_FRAME = 16  # the error stack is drained, boundedly, after every frame


class OpenHapticsDevice(HardwareDriver):
    def __init__(
        self,
        name: str | None = None,
        *,
        library: str | None = None,
        read_timeout_s: float = 0.05,
        reset_encoders: bool = False,
    ):
        self.name = name or None  # None: HD_DEFAULT_DEVICE
        self.library_path = library
        self.read_timeout_s = read_timeout_s
        self.reset_encoders = reset_encoders  # asked for once; a reconnect never resets again
        self._lib = None
        self._handle = hdapi.HD_INVALID_HANDLE
        self._schedule = None
        self._callback = hdapi.SchedulerCallback(
            self._servo
        )  # keep a reference: the library calls it
        self._lock = threading.Lock()
        self._force = (ctypes.c_double * 3)()
        self._limits = PHANTOM_OMNI_LIMITS
        self._centre = np.zeros(3)
        self.calibration_style: int | None = None
        self.model = "PHANTOM (OpenHaptics)"
        self.serial_number = ""
        self._reset_servo_state()

    def _reset_servo_state(self) -> None:
        self._sample = None  # (t_ns, position, velocity, transform, buttons)
        self._fatal: tuple[int, int] | None = None
        self._calibrated = False
        # after a force error, until the stylus is out or a button pressed anew
        self._force_blocked = False
        self._free_commands = 0  # the daemon's zero commands in a row since
        # force ramping in after a resume: frames with force so far
        self._ramp_frames: int | None = None
        self._last_buttons: int | None = None
        self._unlogged: list[int] = []  # error codes the servo thread saw, for read() to log
        self._logged: set[int] = set()
        self.servo_ticks = 0
        self.force_errors = 0
        self.other_errors = 0

    @property
    def _who(self) -> str:
        return f"'{self.name}'" if self.name else "the default OpenHaptics device"

    @property
    def info(self) -> DeviceInfo:
        with self._lock:
            details = {
                "servo_ticks": self.servo_ticks,
                "calibration_style": self.calibration_style,
                "force_errors": self.force_errors,
                "other_errors": self.other_errors,
                "force_stopped": self._force_blocked,
                "last_error": error_name(self._fatal[0]) if self._fatal else None,
            }
        return DeviceInfo(
            kind="openhaptics",
            model=self.model,
            limits=self._limits,
            serial=self.serial_number,
            details=details,
        )

    # lifecycle ------------------------------------------------------------------------
    def _pop_errors(self) -> list[tuple[int, int]]:
        out = []
        for _ in range(MAX_ERRORS_PER_FRAME):
            err = self._lib.hdGetError()
            if err.errorCode == hdapi.HD_SUCCESS:
                break
            out.append((err.errorCode, err.internalErrorCode))
        return out

    def open(self) -> None:
        if self._lib is None:
            self._lib = hdapi.load_library(self.library_path)
        lib = self._lib
        self._reset_servo_state()
        handle = lib.hdInitDevice(self.name.encode() if self.name else None)
        errors = self._pop_errors()
        if errors or handle == hdapi.HD_INVALID_HANDLE:
            code = errors[0][0] if errors else 0
            raise DeviceOpenError(
                f"OpenHaptics could not initialise {self._who}: {error_name(code)} "
                f"(0x{code:04x}{self._describe(code)}); is it connected and set up in the "
                "vendor's configuration tool?"
            )
        self._handle = handle
        lib.hdMakeCurrentDevice(handle)
        self._read_properties()
        self._reset_encoders_if_asked()
        self._schedule = lib.hdScheduleAsynchronous(
            self._callback, None, hdapi.HD_DEFAULT_SCHEDULER_PRIORITY
        )
        lib.hdEnable(hdapi.HD_FORCE_OUTPUT)
        lib.hdStartScheduler()
        errors = self._pop_errors()
        if errors:
            self.close()
            raise DeviceOpenError(
                f"OpenHaptics scheduler did not start: {error_name(errors[0][0])} "
                f"(0x{errors[0][0]:04x})"
            )

    def _describe(self, code: int) -> str:
        text = self._lib.hdGetErrorString(code)
        return f", {text.decode(errors='replace')}" if text else ""

    def _reset_encoders_if_asked(self) -> None:
        """Calibration.c's encoder reset: before the scheduler, at the pose the user holds."""
        if self.calibration_style != hdapi.HD_CALIBRATION_ENCODER_RESET:
            return
        lib = self._lib
        if self.reset_encoders:
            lib.hdUpdateCalibration(hdapi.HD_CALIBRATION_ENCODER_RESET)
            self.reset_encoders = False
            errors = self._pop_errors()
            if errors:
                self._disable()
                raise DeviceOpenError(
                    f"the encoder reset of {self._who} failed: {error_name(errors[0][0])} "
                    f"(0x{errors[0][0]:04x})"
                )
        if lib.hdCheckCalibration() != hdapi.HD_CALIBRATION_OK:
            self._disable()
            spec = ":".join(["openhaptics", *([self.name] if self.name else []), RESET_ENCODERS])
            raise DeviceOpenError(
                f"{self._who} needs an encoder reset: hold the arm at its reset position (all "
                f"links orthogonal) and open it as --device '{spec}'"
            )

    def _read_properties(self) -> None:
        lib = self._lib

        def doubles(param: int, n: int) -> np.ndarray:
            out = (ctypes.c_double * n)()
            lib.hdGetDoublev(param, out)
            return np.array(out[:])

        model = lib.hdGetString(hdapi.HD_DEVICE_MODEL_TYPE)
        if model:
            self.model = model.decode(errors="replace")
        serial = lib.hdGetString(hdapi.HD_DEVICE_SERIAL_NUMBER)
        self.serial_number = serial.decode(errors="replace") if serial else ""
        box = doubles(hdapi.HD_USABLE_WORKSPACE_DIMENSIONS, 6)
        lo, hi = box[:3], box[3:]
        if not np.all(hi > lo):
            lo, hi = (
                np.asarray(PHANTOM_OMNI_LIMITS.workspace_min_mm),
                np.asarray(PHANTOM_OMNI_LIMITS.workspace_max_mm),
            )
        self._centre = (lo + hi) / 2.0
        styles = ctypes.c_int(0)
        lib.hdGetIntegerv(hdapi.HD_CALIBRATION_STYLE, ctypes.byref(styles))
        self.calibration_style = hdapi.preferred_calibration_style(styles.value)
        max_force = (
            float(doubles(hdapi.HD_NOMINAL_MAX_FORCE, 1)[0]) or PHANTOM_OMNI_LIMITS.max_force_n
        )
        continuous = float(doubles(hdapi.HD_NOMINAL_MAX_CONTINUOUS_FORCE, 1)[0])
        stiffness = float(doubles(hdapi.HD_NOMINAL_MAX_STIFFNESS, 1)[0])
        damping_n_s_per_mm = float(doubles(hdapi.HD_NOMINAL_MAX_DAMPING, 1)[0])  # HDAPI's unit
        self._limits = DeviceLimits(
            max_force_n=max_force,
            continuous_force_n=continuous or PHANTOM_OMNI_LIMITS.continuous_force_n,
            max_stiffness_n_per_mm=stiffness or PHANTOM_OMNI_LIMITS.max_stiffness_n_per_mm,
            max_damping_n_s_per_m=damping_n_s_per_mm * 1000.0
            or PHANTOM_OMNI_LIMITS.max_damping_n_s_per_m,
            workspace_min_mm=tuple(float(v) for v in lo - self._centre),
            workspace_max_mm=tuple(float(v) for v in hi - self._centre),
            nominal_rate_hz=1000.0,
        )
        # a parameter this device lacks leaves HD_INVALID_ENUM; the defaults stand
        self._pop_errors()

    def _disable(self) -> None:
        self._lib.hdDisableDevice(self._handle)
        self._handle = hdapi.HD_INVALID_HANDLE

    def close(self) -> None:
        lib = self._lib
        if lib is None or self._handle == hdapi.HD_INVALID_HANDLE:
            return
        with self._lock:
            self._force[:] = [0.0, 0.0, 0.0]
            self.force = np.zeros(3)
            ticks = self.servo_ticks
        deadline = time.monotonic() + 0.02  # let one frame send the zero while the loop still runs
        while self._fatal is None and self.servo_ticks == ticks and time.monotonic() < deadline:
            time.sleep(0.001)
        lib.hdStopScheduler()
        if self._schedule is not None:
            lib.hdUnschedule(self._schedule)
            self._schedule = None
        self._disable()

    # servo thread (the library's, 1 kHz) --------------------------------------------
    def _servo(self, _user_data) -> int:
        lib, h = self._lib, self._handle
        position, velocity, transform = (
            (ctypes.c_double * 3)(),
            (ctypes.c_double * 3)(),
            (ctypes.c_double * 16)(),
        )
        buttons = ctypes.c_int(0)
        lib.hdBeginFrame(h)
        lib.hdGetDoublev(hdapi.HD_CURRENT_POSITION, position)
        lib.hdGetDoublev(hdapi.HD_CURRENT_VELOCITY, velocity)
        lib.hdGetDoublev(hdapi.HD_CURRENT_TRANSFORM, transform)
        lib.hdGetIntegerv(hdapi.HD_CURRENT_BUTTONS, ctypes.byref(buttons))
        calibration = lib.hdCheckCalibration()
        if calibration == hdapi.HD_CALIBRATION_NEEDS_UPDATE and self.calibration_style in (
            hdapi.HD_CALIBRATION_AUTO,
            hdapi.HD_CALIBRATION_INKWELL,
        ):
            lib.hdUpdateCalibration(
                self.calibration_style
            )  # Calibration.c's UpdateCalibrationCallback
        calibrated = calibration == hdapi.HD_CALIBRATION_OK
        tip = np.array(position[:])
        with self._lock:
            if (
                self._force_blocked
                and self._last_buttons is not None
                and buttons.value & ~self._last_buttons
            ):
                self._resume()  # AnchoredSpringForce.c: a new button-down edge re-arms
            self._last_buttons = buttons.value
            rendered = self._output() if calibrated and not self._force_blocked else np.zeros(3)
            out = (ctypes.c_double * 3)(*rendered)
            lib.hdSetDoublev(hdapi.HD_CURRENT_FORCE, out)
        lib.hdEndFrame(h)
        errors = self._pop_errors()
        with self._lock:
            self.servo_ticks += 1
            self._calibrated = calibrated
            self._sample = (
                time.monotonic_ns(),
                tip,
                np.array(velocity[:]),
                np.array(transform[:]).reshape(4, 4).T,
                buttons.value,
            )
            for code, internal in errors:
                if len(self._unlogged) < MAX_ERRORS_PER_FRAME:
                    self._unlogged.append(code)
                if hdapi.is_scheduler_error(code):
                    self._fatal = self._fatal or (code, internal)
                elif hdapi.is_force_error(code) or code == hdapi.HD_DEVICE_FAULT:
                    self.force_errors += 1
                    self._stop_force()
                else:
                    self.other_errors += 1
            ending = self._fatal is not None
        if ending:  # no second frame this tick (HD_ONE_FRAME_LIMIT): the motors go off now
            lib.hdDisable(hdapi.HD_FORCE_OUTPUT)
            self._pop_errors()
            return hdapi.HD_CALLBACK_DONE
        return hdapi.HD_CALLBACK_CONTINUE

    def _output(self) -> np.ndarray:
        """The force to render this frame: the command, ramped in after a resume."""
        force = np.array(self._force[:])
        if self._ramp_frames is None:
            return force
        if np.any(force):  # the ramp's clock runs only while there is force to render
            self._ramp_frames += 1
        scale = min(self._ramp_frames / RESUME_RAMP_FRAMES, 1.0)
        if scale >= 1.0:
            self._ramp_frames = None
        return force * scale

    def _stop_force(self) -> None:
        """A force error: no force until the stylus is out or a button is pressed anew."""
        self._force_blocked = True
        self._free_commands = 0
        self._ramp_frames = None

    def _resume(self) -> None:
        self._force_blocked = False
        self._free_commands = 0
        self._ramp_frames = 0

    # interface ------------------------------------------------------------------------
    def read(self) -> DeviceState:
        with self._lock:
            sample, fatal, calibrated = self._sample, self._fatal, self._calibrated
            unlogged, self._unlogged = self._unlogged, []
        for code in unlogged:  # once per code and session; the counts are in `info.details`
            if code not in self._logged and not hdapi.is_scheduler_error(code):
                self._logged.add(code)
                stops_force = hdapi.is_force_error(code) or code == hdapi.HD_DEVICE_FAULT
                log.warning(
                    "OpenHaptics reported %s (0x%04x): %s",
                    error_name(code),
                    code,
                    "force output stopped until the stylus is out of the contact or a button is "
                    "pressed anew"
                    if stops_force
                    else "the servo loop goes on",
                )
        if fatal is not None:
            raise DeviceFault(
                f"OpenHaptics reported {error_name(fatal[0])} "
                f"(0x{fatal[0]:04x}, internal {fatal[1]})"
            )
        if sample is None or time.monotonic_ns() - sample[0] > self.read_timeout_s * 1e9:
            raise DeviceFault(
                f"the OpenHaptics servo loop has not run for {self.read_timeout_s * 1000:.0f} ms"
            )
        t_ns, position, velocity, transform, buttons = sample
        return DeviceState(
            t_ns=t_ns,
            position_mm=position - self._centre,
            orientation=quaternion_from_matrix(transform[:3, :3]),
            velocity_mm_s=velocity,
            buttons=buttons,
            calibrated=calibrated,
        )

    def write_force(self, force_n) -> None:
        self._command(clamp_force(force_n, self._limits.max_force_n), says_where=True)

    def withhold_force(self) -> None:
        """The daemon withheld this tick's force (a failed or late read, a ramp's first tick):
        zero, and no sign that the stylus has left a contact."""
        self._command(np.zeros(3), says_where=False)

    def zero_force_now(self) -> None:
        """The watchdog's zero while the loop is stalled: rendered at the next frame, and no
        sign that the stylus has left a contact."""
        self._command(np.zeros(3), says_where=False)

    def _command(self, force: np.ndarray, says_where: bool) -> None:
        """`says_where`: the daemon's force for the stylus it read last, valid and on time;
        while force is stopped, exact zeros of those in a row mean the stylus is out."""
        with self._lock:
            self._force[:] = [float(v) for v in force]
            self.force = force
            if not self._force_blocked:
                return
            self._free_commands = self._free_commands + 1 if says_where and not np.any(force) else 0
            if self._free_commands >= FREE_COMMANDS:
                self._resume()


def create(argument: str | None = None, **options) -> OpenHapticsDevice:
    """`openhaptics[:NAME][:reset-encoders]` (NAME as configured, e.g. "Default PHANToM").

    `reset-encoders` says the arm is held at its reset position now (for arms calibrated
    by an encoder reset). Options: library, read_timeout_s.
    """
    name, reset = argument or "", False
    head, sep, tail = name.rpartition(":")
    if tail == RESET_ENCODERS:
        name, reset = (head if sep else ""), True
    return OpenHapticsDevice(
        name or None,
        library=options.get("library"),
        reset_encoders=reset,
        read_timeout_s=float(options.get("read_timeout_s", 0.05)),
    )
