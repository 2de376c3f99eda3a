"""The OpenHaptics HDAPI as ctypes sees it: constants, the error struct, signatures, loading.

Every value is that of the public headers (danepowell/openhaptics, commit
2ce9a4830bd920eccfe3ca5d765fb7bdfd1ae253): usr/include/HD/hdDefines.h (types, error
codes, parameters, calibration values and styles, scheduler priorities), hdDevice.h and
hdScheduler.h (the entry points and their argument types), HDU/hduError.h (the two
error classes).

Error classes. hduError.h names two, implemented in libHDU: a force error ("related to
haptic rendering; typical handling involves resetting contact or simulation state") and
a scheduler error ("a communication, timing or general scheduler error that would
prevent proper operation of the servo loop"). Which codes each holds is in the compiled
hduError.o of usr/lib64/libHDU.a (its hduIsForceError and hduIsSchedulerError, read with
objdump): force errors HD_WARM_MOTORS, HD_EXCEEDED_MAX_FORCE, HD_EXCEEDED_MAX_VELOCITY,
HD_FORCE_ERROR (not HD_EXCEEDED_MAX_FORCE_IMPULSE: the library's impulse check has
already limited the change); scheduler errors HD_COMM_ERROR, HD_COMM_CONFIG_ERROR,
HD_TIMER_ERROR, HD_INVALID_PRIORITY, HD_SCHEDULER_FULL.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

from sasprobe.devices.vendor_library import load_vendor_library

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
HD_DEFAULT_SCHEDULER_PRIORITY = (0xFFFF + 0) // 2  # (HD_MAX + HD_MIN) / 2, HD_MAX = USHRT_MAX
HD_CALIBRATION_OK, HD_CALIBRATION_NEEDS_UPDATE, HD_CALIBRATION_NEEDS_MANUAL_INPUT = (
    0x5000,
    0x5001,
    0x5002,
)
HD_CALIBRATION_ENCODER_RESET, HD_CALIBRATION_AUTO, HD_CALIBRATION_INKWELL = 1 << 0, 1 << 1, 1 << 2

HD_ERRORS = {
    0x0100: "HD_INVALID_ENUM",
    0x0101: "HD_INVALID_VALUE",
    0x0102: "HD_INVALID_OPERATION",
    0x0103: "HD_INVALID_INPUT_TYPE",
    0x0104: "HD_BAD_HANDLE",
    0x0200: "HD_WARM_MOTORS",
    0x0201: "HD_EXCEEDED_MAX_FORCE",
    0x0202: "HD_EXCEEDED_MAX_FORCE_IMPULSE",
    0x0203: "HD_EXCEEDED_MAX_VELOCITY",
    0x0204: "HD_FORCE_ERROR",
    0x0300: "HD_DEVICE_FAULT",
    0x0301: "HD_DEVICE_ALREADY_INITIATED",
    0x0302: "HD_COMM_ERROR",
    0x0303: "HD_COMM_CONFIG_ERROR",
    0x0304: "HD_TIMER_ERROR",
    0x0400: "HD_ILLEGAL_BEGIN",
    0x0401: "HD_ILLEGAL_END",
    0x0402: "HD_FRAME_ERROR",
    0x0500: "HD_INVALID_PRIORITY",
    0x0501: "HD_SCHEDULER_FULL",
    0x0600: "HD_INVALID_LICENSE",
}
HD_DEVICE_FAULT = 0x0300
FORCE_ERRORS = frozenset({0x0200, 0x0201, 0x0203, 0x0204})
SCHEDULER_ERRORS = frozenset({0x0302, 0x0303, 0x0304, 0x0500, 0x0501})

NOT_INSTALLED = (
    "OpenHaptics is not installed: the HD library (libHD.so / hd.dll) was not found; install "
    "the OpenHaptics runtime and your device driver, or set SASPROBE_HD_LIBRARY=/path/to/libHD.so"
)


def error_name(code: int) -> str:
    return HD_ERRORS.get(code, "unknown HD error")


def is_force_error(code: int) -> bool:
    return code in FORCE_ERRORS


def is_scheduler_error(code: int) -> bool:
    return code in SCHEDULER_ERRORS


class HDErrorInfo(ctypes.Structure):
    _fields_ = [
        ("errorCode", ctypes.c_uint),
        ("internalErrorCode", ctypes.c_int),
        ("hHD", ctypes.c_uint),
    ]


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
    "hdDisable": (None, [ctypes.c_uint]),
    "hdBeginFrame": (None, [ctypes.c_uint]),
    "hdEndFrame": (None, [ctypes.c_uint]),
    "hdGetDoublev": (None, [ctypes.c_uint, ctypes.POINTER(ctypes.c_double)]),
    "hdGetIntegerv": (None, [ctypes.c_uint, ctypes.POINTER(ctypes.c_int)]),
    "hdGetString": (ctypes.c_char_p, [ctypes.c_uint]),
    "hdSetDoublev": (None, [ctypes.c_uint, ctypes.POINTER(ctypes.c_double)]),
    "hdScheduleAsynchronous": (
        ctypes.c_ulong,
        [SchedulerCallback, ctypes.c_void_p, ctypes.c_ushort],
    ),
    "hdStartScheduler": (None, []),
    "hdStopScheduler": (None, []),
    "hdUnschedule": (None, [ctypes.c_ulong]),
    "hdCheckCalibration": (ctypes.c_uint, []),
    "hdUpdateCalibration": (None, [ctypes.c_uint]),
}


def load_library(path: str | None = None):
    """The HD library with its signatures declared, or DeviceOpenError(NOT_INSTALLED)."""
    path = path or os.environ.get("SASPROBE_HD_LIBRARY") or ctypes.util.find_library("HD")
    return load_vendor_library(
        [path] if path else [], _SIGNATURES, NOT_INSTALLED, "the OpenHaptics HD library"
    )


def preferred_calibration_style(supported: int) -> int | None:
    """Calibration.c's choice: auto over inkwell over encoder reset (None: the device names
    none)."""
    for style in (HD_CALIBRATION_AUTO, HD_CALIBRATION_INKWELL, HD_CALIBRATION_ENCODER_RESET):
        if supported & style:
            return style
    return None
