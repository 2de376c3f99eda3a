"""A vendor's C library through ctypes: loaded, and every entry point a driver calls declared.

The SDK drivers (forcedimension/dhd.py, openhaptics/hdapi.py) each say where their library
may be and what its entry points take and return; loading it and refusing a library that
lacks an entry point is the same for both.
"""

from __future__ import annotations

import ctypes

from sasprobe.devices.base import DeviceOpenError


def load_vendor_library(paths: list[str], signatures: dict, not_installed: str, what: str):
    """The first of `paths` with each entry point of `signatures` ({name: (restype,
    argtypes)}) declared. DeviceOpenError(`not_installed`) when there is no path or it does
    not load; "PATH is not WHAT: it lacks NAME" when an entry point is missing."""
    if not paths:
        raise DeviceOpenError(not_installed)
    try:
        lib = ctypes.CDLL(paths[0])
    except OSError as exc:
        raise DeviceOpenError(f"{not_installed} ({exc})") from None
    for name, (restype, argtypes) in signatures.items():
        try:
            fn = getattr(lib, name)
        except AttributeError:
            raise DeviceOpenError(f"{paths[0]} is not {what}: it lacks {name}") from None
        fn.restype, fn.argtypes = restype, argtypes
    return lib
