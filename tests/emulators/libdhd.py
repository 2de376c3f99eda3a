"""The stand-in DHD library (fake_libdhd.c): build it, and steer the arm it emulates.

The arm is steered through a control block in a shared file (FAKE_DHD_CONTROL), the same
bytes `struct control` in fake_libdhd.c lays out, so a test reaches the arm whether the
driver runs in this process or in a daemon subprocess. Everything here is in DHD's own
frame and units (dhdc.h, CHAI3D's CMyCustomDevice.cpp l. 424–427): x toward the user,
y right, z up, metres and newtons.
"""

from __future__ import annotations

import ctypes
import mmap
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

SOURCE = Path(__file__).parent / "fake_libdhd.c"
MAX_DEVICES = 4
# dhdc.h device types and error codes (enum dhd_errors, in order)
OMEGA3, OMEGA7_RIGHT, SIGMA7_RIGHT, DELTA3, FALCON = 33, 35, 104, 63, 60
DHD_ERROR_COM, DHD_ERROR_TIMEOUT = 2, 7
HAND_STIFFNESS_N_PER_M = 500.0  # fake_libdhd.c's DEFAULT_HAND_K


class Control(ctypes.Structure):
    """fake_libdhd.c's `struct control`, field for field."""

    _fields_ = [
        ("hand", ctypes.c_double * 3),
        ("hand_speed", ctypes.c_double),
        ("hand_stiffness", ctypes.c_double),
        ("motor_limit", ctypes.c_double),
        ("wrist_angle", ctypes.c_double),
        ("count", ctypes.c_int32),
        ("types", ctypes.c_int32 * MAX_DEVICES),
        ("serials", ctypes.c_int32 * MAX_DEVICES),
        ("buttons", ctypes.c_int32),
        ("link_down", ctypes.c_int32),
        ("link_error", ctypes.c_int32),
        ("timeguard_every", ctypes.c_int32),
        ("handle", ctypes.c_double * 3),
        ("velocity", ctypes.c_double * 3),
        ("force", ctypes.c_double * 3),
        ("max_force", ctypes.c_double),
        ("position_reads", ctypes.c_int64),
        ("timeguards", ctypes.c_int64),
        ("set_force_calls", ctypes.c_int64),
        ("saturated", ctypes.c_int64),
        ("failed_calls", ctypes.c_int64),
        ("steps", ctypes.c_int64),
        ("open_id", ctypes.c_int32),
        ("opens", ctypes.c_int32),
        ("force_enabled", ctypes.c_int32),
        ("enables", ctypes.c_int32),
        ("forces_ignored", ctypes.c_int32),
        ("pad", ctypes.c_int32),
    ]


def build(directory: Path, name: str = "libdhd.so", without_set_force: bool = False) -> Path | None:
    """The compiled library in `directory`, or None when there is no C compiler."""
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        return None
    out = Path(directory) / name
    flags = ["-DFAKE_DHD_WITHOUT_SET_FORCE"] if without_set_force else []
    subprocess.run(
        [
            compiler,
            "-shared",
            "-fPIC",
            "-O2",
            *flags,
            "-o",
            str(out),
            str(SOURCE),
            "-lpthread",
            "-lm",
        ],
        check=True,
        capture_output=True,
        timeout=120,
    )
    size = ctypes.CDLL(str(out)).fake_control_size
    size.restype = ctypes.c_size_t
    if size() != ctypes.sizeof(Control):
        raise RuntimeError(f"struct control is {size()} bytes in C, {ctypes.sizeof(Control)} here")
    return out


class EmulatedDHD:
    """Arms behind the stand-in library: `control` for the test, `hand` (m, DHD frame) for the
    user."""

    def __init__(
        self,
        library: Path,
        *,
        types=(OMEGA3,),
        serials=(12345,),
        hand=(0.0, 0.0, 0.0),
        timeguard_every: int = 2,
        index: int = 0,
    ):
        self.library = Path(library)
        self._folder = Path(tempfile.mkdtemp(prefix="fakedhd"))
        self.control_path = self._folder / "control"
        self.control_path.write_bytes(bytes(ctypes.sizeof(Control)))
        self._file = open(self.control_path, "r+b")
        self._map = mmap.mmap(self._file.fileno(), ctypes.sizeof(Control))
        self.control = Control.from_buffer(self._map)
        c = self.control
        c.count, c.timeguard_every, c.open_id = len(types), timeguard_every, -1
        for i, (kind, serial) in enumerate(zip(types, list(serials) + [0] * len(types))):
            c.types[i], c.serials[i] = kind, serial
        c.hand[:] = [float(v) for v in hand]
        self.index = index
        self.scratch: Path | None = None

    @property
    def device_spec(self) -> str:
        return f"forcedimension:{self.index}"

    @property
    def env(self) -> dict[str, str]:
        return {
            "SASPROBE_DHD_LIBRARY": str(self.library),
            "FAKE_DHD_CONTROL": str(self.control_path),
        }

    def move_hand(self, xyz_m) -> None:
        self.control.hand[:] = [float(v) for v in xyz_m]

    @property
    def handle_m(self) -> tuple[float, float, float]:
        return tuple(self.control.handle)

    @property
    def force_n(self) -> tuple[float, float, float]:
        return tuple(self.control.force)

    def link(self, up: bool, error: int = DHD_ERROR_COM) -> None:
        self.control.link_error = error
        self.control.link_down = 0 if up else 1

    def settled(self, atol_m: float = 2e-5, timeout_s: float = 5.0) -> None:
        """Wait until the handle rests at its hand's target (no force) within `atol_m`."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            c = self.control
            if (
                max(abs(c.handle[i] - c.hand[i]) for i in range(3)) < atol_m
                and max(abs(v) for v in c.velocity) < 1e-3
            ):
                return
            time.sleep(0.005)
        raise AssertionError(
            f"the handle did not settle at {list(self.control.hand)}: {list(self.control.handle)}"
        )

    def close(self) -> None:
        self._file.close()
        shutil.rmtree(self._folder, ignore_errors=True)
        if self.scratch is not None:
            shutil.rmtree(self.scratch, ignore_errors=True)


def launch(**options) -> EmulatedDHD:
    """One emulated arm: `library` (a built stand-in) or a build into a scratch folder
    (removed by `close()`). Other options as EmulatedDHD."""
    library = options.pop("library", None)
    scratch = None
    if library is None:
        scratch = Path(tempfile.mkdtemp(prefix="libdhd"))
        library = build(scratch)
        if library is None:
            raise RuntimeError("no C compiler to build the stand-in DHD library")
    emu = EmulatedDHD(library, **options)
    emu.scratch = scratch
    return emu
