"""Build the stand-in OpenHaptics HD library (fake_libhd.c) with the system's C compiler."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

SOURCE = Path(__file__).parent / "fake_libhd.c"


def build(directory: Path, name: str = "libHD.so") -> Path | None:
    """The compiled library in `directory`, or None when there is no C compiler."""
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        return None
    out = Path(directory) / name
    subprocess.run([compiler, "-shared", "-fPIC", "-O2", "-o", str(out), str(SOURCE), "-lpthread", "-lm"],
                   check=True, capture_output=True, timeout=120)
    return out
