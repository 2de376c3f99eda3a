"""The CLI starts without what it does not use: `sasprobe --help` loads neither numpy nor
gemmi nor any GL or plotting library, `sasprobe info` no GL or plotting library, and the
help still lists every command (each registered in full only when it runs). Start-up
time is measured by `sasprobe bench startup`, not here."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.conftest import REPO_ROOT

PLOTTING_AND_GL = {"matplotlib", "moderngl", "glcontext", "glfw", "PIL", "imageio"}
PROBE = (
    "import runpy, sys, json\n"
    "sys.argv = ['sasprobe'] + sys.argv[1:]\n"
    "try:\n    runpy.run_module('sasprobe', run_name='__main__')\n"
    "except SystemExit:\n    pass\n"
    "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})), file=sys.stderr)\n"
)


def loaded(*argv: str) -> tuple[set[str], str]:
    r = subprocess.run(
        [sys.executable, "-c", PROBE, *argv],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=60,
    )
    return set(json.loads(r.stderr.strip().splitlines()[-1])), r.stdout


def test_help_and_info_load_only_what_they_use():
    modules, out = loaded("--help")
    assert not modules & (PLOTTING_AND_GL | {"numpy", "gemmi", "zmq"}), modules & (
        PLOTTING_AND_GL | {"numpy", "gemmi"}
    )
    from sasprobe.cli.main import command_names

    for name in command_names():
        assert f"    {name}" in out, f"--help does not list {name}"
    modules, out = loaded("info")
    assert "327" in out and not modules & PLOTTING_AND_GL, modules & PLOTTING_AND_GL


BLAS_PROBE = (
    "import os, runpy, sys\n"
    "sys.argv = ['sasprobe', 'info']\n"
    "try:\n    runpy.run_module('sasprobe', run_name='__main__')\n"
    "except SystemExit:\n    pass\n"
    "print('numpy' in sys.modules, os.environ.get('OPENBLAS_NUM_THREADS'), file=sys.stderr)\n"
)


def test_commands_run_numpy_with_one_blas_thread_unless_told_otherwise():
    """OpenBLAS reads its thread count when numpy loads; the CLI sets one thread before any
    command imports numpy (spinning BLAS threads took the renderer's and the haptic loop's
    CPU), and keeps a count the user set."""
    import os

    for given, expected in ((None, "1"), ("3", "3")):
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
        if given is not None:
            env["OPENBLAS_NUM_THREADS"] = given
        r = subprocess.run(
            [sys.executable, "-c", BLAS_PROBE],
            capture_output=True,
            text=True,
            cwd=REPO_ROOT,
            timeout=60,
            env=env,
        )
        assert r.stderr.strip().splitlines()[-1] == f"True {expected}", r.stderr
