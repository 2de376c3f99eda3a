"""PHANTOM Omni / Touch through the vendor's OpenHaptics HD library (ctypes), when installed.

The arms' own wire protocols are not public, so this driver loads the HD library
(`libHD.so`, `hd.dll`) and follows the documented HDAPI flow: hdInitDevice → read the
nominal limits → hdEnable(HD_FORCE_OUTPUT) → hdScheduleAsynchronous(servo callback) →
hdStartScheduler. The callback runs in the library's 1 kHz servo thread: inside
hdBeginFrame/hdEndFrame it reads position, velocity, transform and buttons, writes the
latest force, and checks calibration; an HD error it reports (HD_COMM_ERROR,
HD_EXCEEDED_MAX_FORCE, ...) stops the callback and surfaces as a DeviceFault naming the
code. Enum values are those of OpenHaptics' hdDefines.h.

Calibration: `hdCheckCalibration()` each tick; HD_CALIBRATION_NEEDS_UPDATE is applied with
the device's supported style; HD_CALIBRATION_NEEDS_MANUAL_INPUT means "put the stylus in
the inkwell" and keeps `calibrated=False` (no force) until it is done.

The library is found through SASPROBE_HD_LIBRARY (a path), then the system's library
search (`ctypes.util.find_library("HD")`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import sys
import threading
import time

import numpy as np

from sasprobe.devices.base import (PHANTOM_OMNI_LIMITS, DeviceFault, DeviceInfo, DeviceLimits, DeviceOpenError,
                                   DeviceState)
from sasprobe.devices.support import HardwareDevice, clamp_force, quaternion_from_matrix

log = logging.getLogger("sasprobe.devices.openhaptics")

HD_SUCCESS = 0x0000
HD_INVALID_HANDLE = 0xFFFFFFFF
HD_CURRENT_BUTTONS = 0x2000
HD_CURRENT_POSITION = 0x2050
HD_CURRENT_VELOCITY = 0x2051
HD_CURRENT_TRANSFORM = 0x2052
HD_DEVICE_MODEL_TYPE = 0x2501
HD_DEVICE_SERIAL_NUMBER = 0x2504
HD_USABLE_WORKSPACE_DIMENSIONS = 0x2551
HD_CALIBRATION_STYLE = 0x2555
HD_NOMINAL_MAX_STIFFNESS = 0x2602
HD_NOMINAL_MAX_FORCE = 0x2603
HD_NOMINAL_MAX_CONTINUOUS_FORCE = 0x2604
HD_NOMINAL_MAX_DAMPING = 0x2609
HD_CURRENT_FORCE = 0x2700
HD_FORCE_OUTPUT = 0x4000
HD_CALLBACK_DONE, HD_CALLBACK_CONTINUE = 0, 1
HD_DEFAULT_SCHEDULER_PRIORITY = (0xFFFF + 0) // 2
HD_CALIBRATION_OK, HD_CALIBRATION_NEEDS_UPDATE, HD_CALIBRATION_NEEDS_MANUAL_INPUT = 0x5000, 0x5001, 0x5002
HD_CALIBRATION_ENCODER_RESET, HD_CALIBRATION_AUTO, HD_CALIBRATION_INKWELL = 1, 2, 4

HD_ERRORS = {
    0x0100: "HD_INVALID_ENUM", 0x0101: "HD_INVALID_VALUE", 0x0102: "HD_INVALID_OPERATION",
    0x0103: "HD_INVALID_INPUT_TYPE", 0x0104: "HD_BAD_HANDLE",
    0x0200: "HD_WARM_MOTORS", 0x0201: "HD_EXCEEDED_MAX_FORCE", 0x0202: "HD_EXCEEDED_MAX_FORCE_IMPULSE",
    0x0203: "HD_EXCEEDED_MAX_VELOCITY", 0x0204: "HD_FORCE_ERROR",
    0x0300: "HD_DEVICE_FAULT", 0x0301: "HD_DEVICE_ALREADY_INITIATED", 0x0302: "HD_COMM_ERROR",
    0x0303: "HD_COMM_CONFIG_ERROR", 0x0304: "HD_TIMER_ERROR",
    0x0400: "HD_ILLEGAL_BEGIN", 0x0401: "HD_ILLEGAL_END", 0x0402: "HD_FRAME_ERROR",
    0x0500: "HD_INVALID_PRIORITY", 0x0501: "HD_SCHEDULER_FULL", 0x0600: "HD_INVALID_LICENSE",
}

NOT_INSTALLED = ("OpenHaptics is not installed: the HD library (libHD.so / hd.dll) was not found; install "
                 "the OpenHaptics runtime and your device driver, or set SASPROBE_HD_LIBRARY=/path/to/libHD.so")


class HDErrorInfo(ctypes.Structure):
    _fields_ = [("errorCode", ctypes.c_uint), ("internalErrorCode", ctypes.c_int), ("hHD", ctypes.c_uint)]


# HDCALLBACK is __stdcall on Windows, the C convention elsewhere.
_FUNCTYPE = ctypes.WINFUNCTYPE if sys.platform == "win32" else ctypes.CFUNCTYPE
SchedulerCallback = _FUNCTYPE(ctypes.c_uint, ctypes.c_void_p)

_SIGNATURES = {
    "hdInitDevice": (ctypes.c_uint, [ctypes.c_char_p]),
    "hdDisableDevice": (None, [ctypes.c_uint]),
    "hdMakeCurrentDevice": (None, [ctypes.c_uint]),
    "hdGetError": (HDErrorInfo, []),
    "hdGetErrorString": (ctypes.c_char_p, [ctypes.c_uint]),
    "hdEnable": (None, [ctypes.c_uint]),
    "hdBeginFrame": (None, [ctypes.c_uint]),
    "hdEndFrame": (None, [ctypes.c_uint]),
    "hdGetDoublev": (None, [ctypes.c_uint, ctypes.POINTER(ctypes.c_double)]),
    "hdGetIntegerv": (None, [ctypes.c_uint, ctypes.POINTER(ctypes.c_int)]),
    "hdGetString": (ctypes.c_char_p, [ctypes.c_uint]),
    "hdSetDoublev": (None, [ctypes.c_uint, ctypes.POINTER(ctypes.c_double)]),
    "hdScheduleAsynchronous": (ctypes.c_ulong, [SchedulerCallback, ctypes.c_void_p, ctypes.c_ushort]),
    "hdStartScheduler": (None, []),
    "hdStopScheduler": (None, []),
    "hdUnschedule": (None, [ctypes.c_ulong]),
    "hdCheckCalibration": (ctypes.c_uint, []),
    "hdUpdateCalibration": (None, [ctypes.c_uint]),
}


def error_name(code: int) -> str:
    return HD_ERRORS.get(code, "unknown HD error")


def load_library(path: str | None = None):
    """The HD library with its signatures declared, or DeviceOpenError(NOT_INSTALLED)."""
    path = path or os.environ.get("SASPROBE_HD_LIBRARY") or ctypes.util.find_library("HD")
    if not path:
        raise DeviceOpenError(NOT_INSTALLED)
    try:
        lib = ctypes.CDLL(path)
    except OSError as exc:
        raise DeviceOpenError(f"{NOT_INSTALLED} ({exc})") from None
    for name, (restype, argtypes) in _SIGNATURES.items():
        try:
            fn = getattr(lib, name)
        except AttributeError:
            raise DeviceOpenError(f"{path} is not the OpenHaptics HD library: it lacks {name}") from None
        fn.restype, fn.argtypes = restype, argtypes
    return lib


class OpenHapticsDevice(HardwareDevice):
    def __init__(self, name: str | None = None, *, library: str | None = None, read_timeout_s: float = 0.05):
        self.name = name or None  # None: HD_DEFAULT_DEVICE
        self.library_path = library
        self.read_timeout_s = read_timeout_s
        self._lib = None
        self._handle = HD_INVALID_HANDLE
        self._schedule = None
        self._callback = SchedulerCallback(self._servo)  # keep a reference: the library calls it
        self._lock = threading.Lock()
        self._force = (ctypes.c_double * 3)()
        self._limits = PHANTOM_OMNI_LIMITS
        self._centre = np.zeros(3)
        self._calibration_style = HD_CALIBRATION_AUTO
        self.model = "PHANTOM (OpenHaptics)"
        self._reset_servo_state()

    def _reset_servo_state(self) -> None:
        self._sample = None  # (t_ns, position, velocity, transform, buttons)
        self._error: tuple[int, int] | None = None
        self._calibrated = False
        self.servo_ticks = 0

    @property
    def info(self) -> DeviceInfo:
        return DeviceInfo(kind="openhaptics", model=self.model, limits=self._limits, serial=self.name or "",
                          details={"servo_ticks": self.servo_ticks,
                                   "last_error": error_name(self._error[0]) if self._error else None})

    # lifecycle ------------------------------------------------------------------------
    def open(self) -> None:
        if self._lib is None:
            self._lib = load_library(self.library_path)
        lib = self._lib
        self._reset_servo_state()
        handle = lib.hdInitDevice(self.name.encode() if self.name else None)
        err = lib.hdGetError()
        if err.errorCode != HD_SUCCESS or handle == HD_INVALID_HANDLE:
            raise DeviceOpenError(
                f"OpenHaptics could not initialise '{self.name or 'Default PHANToM'}': "
                f"{error_name(err.errorCode)} (0x{err.errorCode:04x}{self._describe(err.errorCode)}); is it "
                "connected and set up in the vendor's configuration tool?")
        self._handle = handle
        lib.hdMakeCurrentDevice(handle)
        self._read_properties()
        lib.hdEnable(HD_FORCE_OUTPUT)
        self._schedule = lib.hdScheduleAsynchronous(self._callback, None, HD_DEFAULT_SCHEDULER_PRIORITY)
        lib.hdStartScheduler()
        err = lib.hdGetError()
        if err.errorCode != HD_SUCCESS:
            self.close()
            raise DeviceOpenError(f"OpenHaptics scheduler did not start: {error_name(err.errorCode)} "
                                  f"(0x{err.errorCode:04x})")

    def _describe(self, code: int) -> str:
        text = self._lib.hdGetErrorString(code)
        return f", {text.decode(errors='replace')}" if text else ""

    def _read_properties(self) -> None:
        lib = self._lib

        def doubles(param: int, n: int) -> np.ndarray:
            out = (ctypes.c_double * n)()
            lib.hdGetDoublev(param, out)
            return np.array(out[:])

        model = lib.hdGetString(HD_DEVICE_MODEL_TYPE)
        if model:
            self.model = model.decode(errors="replace")
        box = doubles(HD_USABLE_WORKSPACE_DIMENSIONS, 6)
        lo, hi = box[:3], box[3:]
        if not np.all(hi > lo):
            lo, hi = np.asarray(PHANTOM_OMNI_LIMITS.workspace_min_mm), np.asarray(PHANTOM_OMNI_LIMITS.workspace_max_mm)
            self._centre = np.zeros(3)
        else:
            self._centre = (lo + hi) / 2.0
        style = ctypes.c_int(0)
        lib.hdGetIntegerv(HD_CALIBRATION_STYLE, ctypes.byref(style))
        for preferred in (HD_CALIBRATION_AUTO, HD_CALIBRATION_ENCODER_RESET, HD_CALIBRATION_INKWELL):
            if style.value & preferred:
                self._calibration_style = preferred
                break
        max_force = float(doubles(HD_NOMINAL_MAX_FORCE, 1)[0]) or PHANTOM_OMNI_LIMITS.max_force_n
        self._limits = DeviceLimits(
            max_force_n=max_force,
            continuous_force_n=float(doubles(HD_NOMINAL_MAX_CONTINUOUS_FORCE, 1)[0]) or PHANTOM_OMNI_LIMITS.continuous_force_n,
            max_stiffness_n_per_mm=float(doubles(HD_NOMINAL_MAX_STIFFNESS, 1)[0]) or PHANTOM_OMNI_LIMITS.max_stiffness_n_per_mm,
            # HDAPI reports damping in N·s/mm
            max_damping_n_s_per_m=float(doubles(HD_NOMINAL_MAX_DAMPING, 1)[0]) * 1000.0 or PHANTOM_OMNI_LIMITS.max_damping_n_s_per_m,
            workspace_min_mm=tuple(float(v) for v in lo - self._centre),
            workspace_max_mm=tuple(float(v) for v in hi - self._centre),
            nominal_rate_hz=1000.0,
        )

    def close(self) -> None:
        lib = self._lib
        if lib is None or self._handle == HD_INVALID_HANDLE:
            return
        with self._lock:
            self._force[:] = [0.0, 0.0, 0.0]
            self.force = np.zeros(3)
        lib.hdStopScheduler()
        if self._schedule is not None:
            lib.hdUnschedule(self._schedule)
            self._schedule = None
        lib.hdDisableDevice(self._handle)
        self._handle = HD_INVALID_HANDLE

    # servo thread (the library's, 1 kHz) --------------------------------------------
    def _servo(self, _user_data) -> int:
        lib, h = self._lib, self._handle
        position, velocity, transform = (ctypes.c_double * 3)(), (ctypes.c_double * 3)(), (ctypes.c_double * 16)()
        buttons = ctypes.c_int(0)
        lib.hdBeginFrame(h)
        lib.hdGetDoublev(HD_CURRENT_POSITION, position)
        lib.hdGetDoublev(HD_CURRENT_VELOCITY, velocity)
        lib.hdGetDoublev(HD_CURRENT_TRANSFORM, transform)
        lib.hdGetIntegerv(HD_CURRENT_BUTTONS, ctypes.byref(buttons))
        calibration = lib.hdCheckCalibration()
        if calibration == HD_CALIBRATION_NEEDS_UPDATE:
            lib.hdUpdateCalibration(self._calibration_style)
        calibrated = calibration == HD_CALIBRATION_OK
        with self._lock:
            force = self._force if calibrated else (ctypes.c_double * 3)()
            lib.hdSetDoublev(HD_CURRENT_FORCE, force)
        lib.hdEndFrame(h)
        err = lib.hdGetError()
        with self._lock:
            self.servo_ticks += 1
            self._calibrated = calibrated
            self._sample = (time.monotonic_ns(), np.array(position[:]), np.array(velocity[:]),
                            np.array(transform[:]).reshape(4, 4).T, buttons.value)
            if err.errorCode != HD_SUCCESS:
                self._error = (err.errorCode, err.internalErrorCode)
                return HD_CALLBACK_DONE
        return HD_CALLBACK_CONTINUE

    # interface ------------------------------------------------------------------------
    def read(self) -> DeviceState:
        with self._lock:
            sample, error, calibrated = self._sample, self._error, self._calibrated
        if error is not None:
            raise DeviceFault(f"OpenHaptics reported {error_name(error[0])} (0x{error[0]:04x}, "
                              f"internal {error[1]})")
        if sample is None or time.monotonic_ns() - sample[0] > self.read_timeout_s * 1e9:
            raise DeviceFault(f"the OpenHaptics servo loop has not run for {self.read_timeout_s * 1000:.0f} ms")
        t_ns, position, velocity, transform, buttons = sample
        return DeviceState(t_ns=t_ns, position_mm=position - self._centre,
                           orientation=quaternion_from_matrix(transform[:3, :3]), velocity_mm_s=velocity,
                           buttons=buttons, calibrated=calibrated)

    def write_force(self, force_n) -> None:
        force = clamp_force(force_n, self._limits.max_force_n)
        with self._lock:
            self._force[:] = [float(v) for v in force]
            self.force = force


def create(argument: str | None = None, **options) -> OpenHapticsDevice:
    """`openhaptics[:NAME]` (NAME as configured, e.g. "Default PHANToM"). Options: library."""
    return OpenHapticsDevice(argument or None, library=options.get("library"),
                             read_timeout_s=float(options.get("read_timeout_s", 0.05)))
