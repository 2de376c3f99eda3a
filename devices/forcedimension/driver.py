"""Force Dimension arms (omega, sigma, delta, lambda; the Novint Falcon through DHD) through
the SDK's DHD library, as a HapticDevice.

Opening follows CHAI3D's `cDeltaDevice` (chai3d/chai3d @ 7c76b1f2,
src/devices/CDeltaDevices.cpp): `dhdGetDeviceCount`, `dhdOpenID(index)` (its result is
the ID every later call passes), `dhdGetSystemType` for the model's limits
(`models.py`), then `dhdEnableForce(DHD_ON)`, without which the arm renders nothing.
Each `read()` calls `dhdGetPosition` (DHD_TIMEGUARD is a success: the position of the
last refresh), `dhdGetLinearVelocity` (its DHD_ERROR_TIMEOUT, two reads missing from its
20 ms window, is no fault: the finite-difference estimate stands in), the wrist's
rotation where there is one, and `dhdGetButtonMask` (bit i = button i, passed to the
daemon's button map as it is). `write_force()` clamps, maps and calls `dhdSetForce`
(DHD_MOTOR_SATURATED is a success). Any call that returns -1 raises DeviceFault naming
`dhdErrorGetLast()`, read on the calling thread, where the SDK keeps it; the daemon then
writes zero and, once the arm has failed for 100 ms, calls `reconnect()`, which closes,
reopens and enables force again (a device that lost its link forgets that force was on).
"""

from __future__ import annotations

import ctypes
import logging
import time

import numpy as np
from sasprobe.devices.base import (
    IDENTITY_QUATERNION,
    DeviceFault,
    DeviceInfo,
    DeviceOpenError,
    DeviceState,
)
from sasprobe.devices.forcedimension import dhd, frame
from sasprobe.devices.forcedimension.models import DhdModel, before_open_limits, model_for
from sasprobe.devices.hardware import HardwareDriver, VelocityFilter, clamp_force
from sasprobe.devices.kinematics import quaternion_from_matrix

log = logging.getLogger("sasprobe.devices.forcedimension")


class ForceDimensionDevice(HardwareDriver):
    def __init__(self, index: int = 0, *, library: str | None = None):
        if index < 0:
            raise DeviceOpenError(f"forcedimension:{index}: the index counts the arms from 0")
        self.index = index
        self.library_path = library
        self._lib = None
        self._id: int | None = None  # what dhdOpenID returned
        self.model: DhdModel | None = None
        self.system_type: int | None = None
        self.system_name = ""
        self.serial = ""
        self.force = np.zeros(3)
        self._has_wrist = False
        self._velocity = VelocityFilter()
        self._c = [ctypes.c_double() for _ in range(3)]
        self._refs = [ctypes.byref(v) for v in self._c]
        self._matrix = (ctypes.c_double * 9)()
        self.timeguards = self.saturations = self.velocity_estimates = 0

    @property
    def info(self) -> DeviceInfo:
        details = {
            "index": self.index,
            "system_type": self.system_type,
            "system_name": self.system_name,
            "timeguard_reads": self.timeguards,
            "saturated_writes": self.saturations,
            "velocity_estimated": self.velocity_estimates,
        }
        model = self.model
        return DeviceInfo(
            kind="forcedimension",
            model=model.name if model else "Force Dimension arm (not opened yet)",
            limits=model.limits if model else before_open_limits(),
            serial=self.serial,
            details=details,
        )

    # lifecycle ------------------------------------------------------------------------
    def _error(self) -> str:
        code = self._lib.dhdErrorGetLast()
        return f"{dhd.error_name(code)} ({code})"

    def open(self) -> None:
        if self._lib is None:
            self._lib = dhd.load_library(self.library_path)
        lib = self._lib
        count = lib.dhdGetDeviceCount()
        if count < 0:
            raise DeviceOpenError(
                f"the Force Dimension SDK could not count its devices: {self._error()}"
            )
        if self.index >= count:
            raise DeviceOpenError(
                f"no Force Dimension arm at index {self.index}: the SDK sees {count} (is it "
                "plugged in, powered, and readable by your user? see docs/connect-your-arm.md)"
            )
        device_id = lib.dhdOpenID(self.index)
        if device_id < 0:
            raise DeviceOpenError(
                f"the Force Dimension arm at index {self.index} did not open: {self._error()}"
            )
        self._id = device_id
        self.system_type = lib.dhdGetSystemType(device_id)
        self.model = model_for(self.system_type)
        name = lib.dhdGetSystemName(device_id)
        self.system_name = name.decode(errors="replace") if name else ""
        serial = ctypes.c_ushort(0)
        self.serial = (
            str(serial.value)
            if lib.dhdGetSerialNumber(ctypes.byref(serial), device_id) >= 0
            else ""
        )
        self._has_wrist = bool(lib.dhdHasWrist(device_id))
        self._velocity.reset()
        self.force = np.zeros(3)
        if (
            lib.dhdSetForce(0.0, 0.0, 0.0, device_id) < 0
            or lib.dhdEnableForce(dhd.DHD_ON, device_id) < 0
        ):
            error = self._error()
            self.close()
            raise DeviceOpenError(
                f"the Force Dimension arm at index {self.index} refused force output: {error}"
            )

    def close(self) -> None:
        self.force = np.zeros(3)
        if self._id is None:
            return
        lib, device_id, self._id = self._lib, self._id, None
        # an arm that cannot hear it has lost force already
        lib.dhdSetForce(0.0, 0.0, 0.0, device_id)
        lib.dhdClose(device_id)

    def reconnect(self) -> None:
        super().reconnect()
        log.info("Force Dimension arm %d reopened, force enabled again", self.index)

    # interface ------------------------------------------------------------------------
    def read(self) -> DeviceState:
        lib, device_id = self._lib, self._id
        if device_id is None:
            raise DeviceFault("the Force Dimension arm is not open")
        result = lib.dhdGetPosition(*self._refs, device_id)
        t_ns = time.monotonic_ns()
        if result < 0:
            raise DeviceFault(f"dhdGetPosition failed: {self._error()}")
        if result == dhd.DHD_TIMEGUARD:
            self.timeguards += 1
        position = frame.position_mm([v.value for v in self._c] + np.asarray(self.model.offset_m))
        estimate = self._velocity.update(t_ns, position)
        if lib.dhdGetLinearVelocity(*self._refs, device_id) >= 0:
            velocity = frame.velocity_mm_s([v.value for v in self._c])
        elif lib.dhdErrorGetLast() == dhd.DHD_ERROR_TIMEOUT:  # fewer than two reads in its window
            velocity = estimate
            self.velocity_estimates += 1
        else:
            raise DeviceFault(f"dhdGetLinearVelocity failed: {self._error()}")
        orientation = np.array(IDENTITY_QUATERNION)
        if self._has_wrist:
            if lib.dhdGetOrientationFrame(ctypes.byref(self._matrix), device_id) < 0:
                raise DeviceFault(f"dhdGetOrientationFrame failed: {self._error()}")
            orientation = quaternion_from_matrix(
                frame.rotation(np.reshape(self._matrix[:], (3, 3)))
            )
        buttons = int(lib.dhdGetButtonMask(device_id))
        return DeviceState(
            t_ns=t_ns,
            position_mm=position,
            orientation=orientation,
            velocity_mm_s=velocity,
            buttons=buttons,
        )

    def write_force(self, force_n) -> None:
        limit = (
            self.model.max_force_n if self.model is not None else before_open_limits().max_force_n
        )
        self.force = clamp_force(force_n, limit)
        if self._id is None:
            return
        fx, fy, fz = (float(v) for v in frame.dhd_force(self.force))
        result = self._lib.dhdSetForce(fx, fy, fz, self._id)
        if result < 0:
            raise DeviceFault(f"dhdSetForce failed: {self._error()}")
        if result == dhd.DHD_MOTOR_SATURATED:
            self.saturations += 1


def list_arms(library: str | None = None) -> list[dict]:
    """Each arm the SDK counts: {index, model, serial} once opened and closed again (as
    CHAI3D's constructor does), or {index, error} for one that would not open (in use by
    another program, not ready). DeviceOpenError without the library."""
    lib = dhd.load_library(library)
    arms = []
    for index in range(max(lib.dhdGetDeviceCount(), 0)):
        device_id = lib.dhdOpenID(index)
        if device_id < 0:
            code = lib.dhdErrorGetLast()
            arms.append({"index": index, "error": f"{dhd.error_name(code)} ({code})"})
            continue
        serial = ctypes.c_ushort(0)
        has_serial = lib.dhdGetSerialNumber(ctypes.byref(serial), device_id) >= 0
        arms.append(
            {
                "index": index,
                "model": model_for(lib.dhdGetSystemType(device_id)).name,
                "serial": str(serial.value) if has_serial else "",
            }
        )
        lib.dhdClose(device_id)
    return arms


def create(argument: str | None = None, **options) -> ForceDimensionDevice:
    """`forcedimension[:INDEX]`: the INDEX-th arm the SDK counts (default 0). Option: library."""
    text = (argument or "").strip()
    try:
        index = int(text) if text else 0
    except ValueError:
        raise DeviceOpenError(f"forcedimension:{text}: expected an arm index (0, 1, ...)") from None
    return ForceDimensionDevice(index, library=options.get("library"))
