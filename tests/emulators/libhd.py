"""The stand-in OpenHaptics HD library (fake_libhd.c): build it, and steer the device it emulates.

The device is steered through a control block in a shared file (FAKE_HD_CONTROL), the
same bytes `struct control` in fake_libhd.c lays out, so a test reaches the device
whether the driver runs in this process or in a daemon subprocess.

Constants below are those of the public HDAPI header hdDefines.h (danepowell/openhaptics,
commit 2ce9a4830bd920eccfe3ca5d765fb7bdfd1ae253, usr/include/HD/hdDefines.h).
"""

from __future__ import annotations

import ctypes
import mmap
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

SOURCE = Path(__file__).parent / "fake_libhd.c"

# hdDefines.h
HD_CALIBRATION_ENCODER_RESET, HD_CALIBRATION_AUTO, HD_CALIBRATION_INKWELL = 1 << 0, 1 << 1, 1 << 2
HD_CALIBRATION_OK, HD_CALIBRATION_NEEDS_UPDATE, HD_CALIBRATION_NEEDS_MANUAL_INPUT = (
    0x5000,
    0x5001,
    0x5002,
)
HD_INVALID_ENUM, HD_WARM_MOTORS, HD_EXCEEDED_MAX_VELOCITY, HD_DEVICE_FAULT, HD_COMM_ERROR = (
    0x0100,
    0x0200,
    0x0203,
    0x0300,
    0x0302,
)
HD_EXCEEDED_MAX_FORCE, HD_EXCEEDED_MAX_FORCE_IMPULSE, HD_FORCE_ERROR = 0x0201, 0x0202, 0x0204
HD_DEVICE_BUTTON_1 = 1 << 0

# fake_libhd.c's MODELS, by the name a test gives them
MODELS = {"touch": 0, "desktop": 1, "premium": 2}

# fake_libhd.c's model 0: the usable box's centre; the hand's spring
USABLE_BOX_CENTRE = (0.0, 0.0, -35.0)
HAND_STIFFNESS_N_PER_MM = 0.5
UNCALIBRATED_OFFSET = (3.0, -4.0, 5.0)


class Control(ctypes.Structure):
    """fake_libhd.c's `struct control`, field for field."""

    _fields_ = [
        ("hand", ctypes.c_double * 3),
        ("yaw", ctypes.c_double),
        ("buttons", ctypes.c_int32),
        ("inkwell", ctypes.c_int32),
        ("plugged", ctypes.c_int32),
        ("styles", ctypes.c_int32),
        ("inject_code", ctypes.c_int32),
        ("inject_frames", ctypes.c_int32),
        ("model", ctypes.c_int32),
        ("serial", ctypes.c_char * 32),
        ("force", ctypes.c_double * 3),
        ("max_force", ctypes.c_double),
        ("reset_distance_mm", ctypes.c_double),
        ("frames", ctypes.c_int64),
        ("forces_clamped", ctypes.c_int64),
        ("force_enabled", ctypes.c_int32),
        ("scheduler_running", ctypes.c_int32),
        ("resets", ctypes.c_int32),
        ("resets_while_running", ctypes.c_int32),
        ("last_update_style", ctypes.c_int32),
        ("calibration", ctypes.c_int32),
        ("initialised", ctypes.c_int32),
        ("callback_done", ctypes.c_int32),
        ("max_step", ctypes.c_double),
        ("stop_calls_on_error", ctypes.c_int32),
        ("halted", ctypes.c_int32),
    ]


def build(directory: Path, name: str = "libHD.so") -> Path | None:
    """The compiled library in `directory`, or None when there is no C compiler."""
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        return None
    out = Path(directory) / name
    subprocess.run(
        [compiler, "-shared", "-fPIC", "-O2", "-o", str(out), str(SOURCE), "-lpthread", "-lm"],
        check=True,
        capture_output=True,
        timeout=120,
    )
    size = ctypes.CDLL(str(out)).fake_control_size
    size.restype = ctypes.c_size_t
    if size() != ctypes.sizeof(Control):
        raise RuntimeError(f"struct control is {size()} bytes in C, {ctypes.sizeof(Control)} here")
    return out


class Hand:
    """The user's hand on the stylus (library frame, mm): `hand.target = (x, y, z)`."""

    def __init__(self, control: Control):
        self._control = control

    @property
    def target(self) -> tuple[float, float, float]:
        return tuple(self._control.hand)

    @target.setter
    def target(self, xyz) -> None:
        self._control.hand[:] = [float(v) for v in xyz]


class EmulatedHD:
    """One emulated arm behind the stand-in library: `control` for the test, `hand` for the user."""

    def __init__(
        self,
        library: Path,
        *,
        styles: int = HD_CALIBRATION_INKWELL,
        hand=(0.0, 0.0, 0.0),
        inkwell: bool = False,
        name: str | None = None,
        reset_encoders: bool = False,
        model: str = "touch",
        serial: str = "",
    ):
        self.library = Path(library)
        self._folder = Path(tempfile.mkdtemp(prefix="fakehd"))
        self.control_path = self._folder / "control"
        self.control_path.write_bytes(bytes(ctypes.sizeof(Control)))
        self._file = open(self.control_path, "r+b")
        self._map = mmap.mmap(self._file.fileno(), ctypes.sizeof(Control))
        self.control = Control.from_buffer(self._map)
        self.control.styles, self.control.plugged, self.control.inkwell = styles, 1, int(inkwell)
        self.control.model, self.control.serial = MODELS[model], serial.encode()
        self.hand = Hand(self.control)
        self.hand.target = hand
        self.name = name
        self.reset_encoders = reset_encoders
        self.scratch: Path | None = None

    @property
    def device_spec(self) -> str:
        parts = (
            ["openhaptics"]
            + ([self.name] if self.name else [])
            + (["reset-encoders"] if self.reset_encoders else [])
        )
        return ":".join(parts)

    @property
    def env(self) -> dict[str, str]:
        return {"SASPROBE_HD_LIBRARY": str(self.library), "FAKE_HD_CONTROL": str(self.control_path)}

    @property
    def applied_force(self) -> tuple[float, float, float]:
        return tuple(self.control.force)

    def inject(self, code: int, frames: int = 1) -> None:
        """Raise HD error `code` at the end of the next `frames` servo frames."""
        self.control.inject_code, self.control.inject_frames = code, frames

    def unplug(self) -> None:
        self.control.plugged = 0

    def replug(self) -> None:
        self.control.plugged = 1

    def wait_frames(self, n: int, timeout_s: float = 5.0) -> None:
        target, deadline = self.control.frames + n, time.monotonic() + timeout_s
        while self.control.frames < target:
            if time.monotonic() > deadline:
                raise AssertionError(f"the servo loop ran no {n} frames in {timeout_s} s")
            time.sleep(0.001)

    def close(self) -> None:
        """Remove the control file (a library that mapped it keeps its pages until it maps
        another)."""
        self._file.close()
        shutil.rmtree(self._folder, ignore_errors=True)
        if self.scratch is not None:  # the library launch() built for this arm alone
            shutil.rmtree(self.scratch, ignore_errors=True)


def launch(**options) -> EmulatedHD:
    """One emulated arm: `library` (a built stand-in) or a build into `directory` (or a
    scratch folder, removed by `close()`). Other options as EmulatedHD: styles (default
    inkwell only), hand, inkwell (True: the stylus starts in the inkwell, so the arm
    calibrates at once), name, reset_encoders, model (a key of MODELS), serial."""
    library, directory = options.pop("library", None), options.pop("directory", None)
    scratch = None
    if library is None:
        scratch = None if directory else Path(tempfile.mkdtemp(prefix="libhd"))
        library = build(Path(directory) if directory else scratch)
        if library is None:
            raise RuntimeError("no C compiler to build the stand-in HD library")
    emu = EmulatedHD(library, **options)
    emu.scratch = scratch
    return emu
