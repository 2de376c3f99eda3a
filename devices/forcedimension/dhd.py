"""The Force Dimension DHD library as ctypes sees it: constants, signatures, loading.

Values are those of the SDK's public C header `dhdc.h`, in two releases: 3.7.0-pre
(WPI-AIM/ambf @ 2d674b6e, external/DHD/include/dhdc.h) and 3.17.5 (chai3d/chai3d @
7c76b1f2, externals/DHD/include/dhdc.h); devices/README.md gives the lines. Every device
call takes the device ID as its last argument (a C `char`), returns a value ≥ 0 on
success and -1 on error, the error code then being the calling thread's
`dhdErrorGetLast()`. Only entry points present in both releases are used.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import glob
import os
import platform

from sasprobe.devices.vendor_library import load_vendor_library

DHD_ON = 1
DHD_TIMEGUARD = 1  # dhdGetPosition: a success, the position of the last refresh
DHD_MOTOR_SATURATED = 2  # dhdSetForce: a success, the force was saturated
DHD_ERROR_TIMEOUT = 7

ERROR_NAMES = (  # enum dhd_errors, in order
    "DHD_NO_ERROR",
    "DHD_ERROR",
    "DHD_ERROR_COM",
    "DHD_ERROR_DHC_BUSY",
    "DHD_ERROR_NO_DRIVER_FOUND",
    "DHD_ERROR_NO_DEVICE_FOUND",
    "DHD_ERROR_NOT_AVAILABLE",
    "DHD_ERROR_TIMEOUT",
    "DHD_ERROR_GEOMETRY",
    "DHD_ERROR_EXPERT_MODE_DISABLED",
    "DHD_ERROR_NOT_IMPLEMENTED",
    "DHD_ERROR_OUT_OF_MEMORY",
    "DHD_ERROR_DEVICE_NOT_READY",
    "DHD_ERROR_FILE_NOT_FOUND",
    "DHD_ERROR_CONFIGURATION",
    "DHD_ERROR_INVALID_INDEX",
    "DHD_ERROR_DEPRECATED",
    "DHD_ERROR_NULL_ARGUMENT",
    "DHD_ERROR_REDUNDANT_FAIL",
    "DHD_ERROR_NOT_ENABLED",
    "DHD_ERROR_DEVICE_IN_USE",
    "DHD_ERROR_INVALID",
)

NOT_INSTALLED = (
    "the Force Dimension SDK is not installed: its DHD library (libdhd.so / dhd64.dll) was not "
    "found; install the SDK from Force Dimension, or set SASPROBE_DHD_LIBRARY=/path/to/libdhd.so"
)

_D = ctypes.POINTER(ctypes.c_double)
_ID = ctypes.c_byte  # char ID

_SIGNATURES = {
    "dhdErrorGetLast": (ctypes.c_int, []),
    "dhdErrorGetStr": (ctypes.c_char_p, [ctypes.c_int]),
    "dhdGetDeviceCount": (ctypes.c_int, []),
    "dhdOpenID": (ctypes.c_int, [_ID]),
    "dhdClose": (ctypes.c_int, [_ID]),
    "dhdGetSystemType": (ctypes.c_int, [_ID]),
    "dhdGetSystemName": (ctypes.c_char_p, [_ID]),
    "dhdGetSerialNumber": (ctypes.c_int, [ctypes.POINTER(ctypes.c_ushort), _ID]),
    "dhdEnableForce": (ctypes.c_int, [ctypes.c_ubyte, _ID]),
    "dhdGetPosition": (ctypes.c_int, [_D, _D, _D, _ID]),
    "dhdGetLinearVelocity": (ctypes.c_int, [_D, _D, _D, _ID]),
    "dhdGetOrientationFrame": (ctypes.c_int, [ctypes.POINTER(ctypes.c_double * 9), _ID]),
    "dhdHasWrist": (ctypes.c_bool, [_ID]),
    "dhdGetButtonMask": (ctypes.c_uint, [_ID]),
    "dhdSetForce": (ctypes.c_int, [ctypes.c_double, ctypes.c_double, ctypes.c_double, _ID]),
}


def error_name(code: int) -> str:
    return ERROR_NAMES[code] if 0 <= code < len(ERROR_NAMES) else f"DHD error {code}"


def candidates() -> list[str]:
    """Where the DHD library may be: SASPROBE_DHD_LIBRARY alone when set; else the linker's
    search for libdhd and libdrd (libdrd carries the DHD calls too), then the SDK's own
    folder under $FDSDK (lib/release/lin-MACHINE-gcc, as forcedimension-core 1.0.0 looks)."""
    forced = os.environ.get("SASPROBE_DHD_LIBRARY")
    if forced:
        return [forced]
    found = [p for p in (ctypes.util.find_library("dhd"), ctypes.util.find_library("drd")) if p]
    sdk = os.environ.get("FDSDK")
    if sdk:
        folder = os.path.join(sdk, "lib", "release", f"lin-{platform.machine()}-gcc")
        found += sorted(glob.glob(os.path.join(folder, "libdhd.so*")))[-1:]
    return found


def load_library(path: str | None = None):
    """The DHD library with its signatures declared, or DeviceOpenError (not installed, or
    a library that lacks one of the entry points, named)."""
    return load_vendor_library(
        [path] if path else candidates(),
        _SIGNATURES,
        NOT_INSTALLED,
        "the Force Dimension DHD library",
    )
