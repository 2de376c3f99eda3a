"""Shared fixtures: the reference PDB structures (tests/data/pdb), the embedded structure, one
headless GL context (checked for GL errors after every test that uses it), a real X server
for the window tests, the stand-in OpenHaptics library and Inverse Service, a helper to run
the real CLI, a check that no test leaves the test process at a real-time priority, and
every message received from a daemon or read from a recording checked against the
protocol's schemas."""

from __future__ import annotations

import os
import select
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sasprobe.cli.main import one_blas_thread
from sasprobe.cli.reference_data import reference_structures

one_blas_thread()  # numpy as the CLI runs it, before it loads (nothing above loads it)
# The shared helpers' and references' asserts explain themselves as the tests' do.
pytest.register_assert_rewrite("tests.support", "tests.references")

REPO_ROOT = Path(__file__).resolve().parent.parent
X_SCREEN = (640, 480)


def in_ci() -> bool:
    """CI sets CI=true (.ci/run does): there every test must run, so what would be a skip for a
    missing dependency (an X server, OpenGL, the reference structures) is a failure."""
    return os.environ.get("CI", "").lower() == "true"


def skip_or_fail(reason: str) -> None:
    if in_ci():
        pytest.fail(f"{reason} (CI=true: a CI machine must have it)")
    pytest.skip(reason)


@pytest.fixture(scope="session")
def reference_entries():
    entries = reference_structures()
    if not entries:
        skip_or_fail("the reference structures (tests/data/pdb) are missing from this checkout")
    return entries


@pytest.fixture(scope="session")
def reference_by_id(reference_entries):
    return {e.id: e for e in reference_entries}


@pytest.fixture(scope="session")
def crambin():
    """The embedded structure (1CRN, 327 atoms)."""
    from sasprobe.molecule import load_default

    return load_default()


@pytest.fixture(scope="session")
def gl():
    """The session's headless EGL context (Mesa's llvmpipe is enough), or a skip where none
    can be made. Every test that uses it, directly or through another fixture, must leave
    no GL error behind (checked by _gl_checks below)."""
    from sasprobe.render.gl.context import GLUnavailable, create_headless_context

    try:
        ctx = create_headless_context()
    except GLUnavailable as exc:
        skip_or_fail(f"no headless OpenGL context: {exc}")
    yield ctx
    ctx.release()


@pytest.fixture(scope="session")
def crambin_grid(gl, crambin):
    """1CRN's uniform grid (expanded by the default probe radius) on the GPU."""
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS
    from sasprobe.render.lighting.uploaded_grid import UploadedGrid

    grid = UploadedGrid.from_structure(gl, crambin, DEFAULT_PROBE_RADIUS)
    yield grid
    grid.release()


@pytest.fixture(scope="session")
def hd_library(tmp_path_factory):
    """The stand-in OpenHaptics HD library (tests/emulators/fake_libhd.c), built once."""
    from tests.emulators import libhd

    out = libhd.build(tmp_path_factory.mktemp("libhd"))
    if out is None:
        skip_or_fail("no C compiler to build the stand-in HD library")
    return out


@pytest.fixture
def hd_arm(hd_library, monkeypatch):
    """A factory: an emulated OpenHaptics arm (options as libhd.EmulatedHD) and a driver
    pointed at it; both closed after the test."""
    from sasprobe.devices.openhaptics.driver import OpenHapticsDevice

    from tests.emulators import libhd

    made = []

    def make(reset_encoders=False, name=None, **options):
        emu = libhd.launch(library=hd_library, **options)
        monkeypatch.setenv("FAKE_HD_CONTROL", str(emu.control_path))
        dev = OpenHapticsDevice(name, library=str(hd_library), reset_encoders=reset_encoders)
        made.append((dev, emu))
        return dev, emu

    yield make
    for dev, emu in made:
        dev.close()
        emu.close()


@pytest.fixture
def inverse_service():
    """A factory: a stand-in Haply Inverse Service (tests/emulators/inverse_service.py) on
    loopback; every one made is closed after the test."""
    from tests.emulators.inverse_service import InverseService

    made = []

    def make(**options):
        svc = InverseService(**options)
        made.append(svc)
        return svc

    yield make
    for svc in made:
        svc.close()


def _drain_gl_errors(ctx) -> list[str]:
    errors = []
    while len(errors) < 16:  # glGetError reports one flag per call
        error = ctx.error
        if error == "GL_NO_ERROR":
            break
        errors.append(error)
    return errors


@pytest.fixture(autouse=True, scope="session")
def _messages_checked_against_the_schemas():
    """Every reply, scene and pose a test receives through sasprobe's clients, and every
    message of every recording it reads through sasprobe's reader, is checked against
    protocol/schemas/ (tests/support/schema_check.py)."""
    from tests.support.schema_check import checking_clients, checking_recordings

    with checking_clients(), checking_recordings():
        yield


@pytest.fixture(autouse=True)
def _scheduling_given_back():
    """A daemon run in this process must give back the real-time priority its loop took:
    otherwise every later test's processes (daemons, renderers, ffmpeg) inherit it and
    compete with the next daemon's loop."""
    before = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    yield
    after = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    if after != before:
        os.sched_setscheduler(0, before[0], os.sched_param(before[1]))
        pytest.fail(
            f"the test left the test process at scheduling policy {after[0]}, priority {after[1]}"
        )


@pytest.fixture(autouse=True)
def _gl_checks(request):
    """For tests that use `gl`: the OpenGL version a module needs (`pytest.mark.needs_gl(430)`)
    and no GL error left behind."""
    if "gl" not in request.fixturenames:
        yield
        return
    ctx = request.getfixturevalue("gl")
    needed = request.node.get_closest_marker("needs_gl")
    if needed is not None and ctx.version_code < needed.args[0]:
        pytest.fail(
            f"needs OpenGL {needed.args[0] / 100:.1f}; "
            f"{ctx.info['GL_RENDERER']} offers {ctx.info['GL_VERSION']}"
        )
    _drain_gl_errors(ctx)  # an earlier test's leftovers are that test's failure, not this one's
    yield
    errors = _drain_gl_errors(ctx)
    assert not errors, f"OpenGL error(s) after the test: {', '.join(errors)}"


@pytest.fixture(scope="module")
def xvfb(gl):
    """A private X server (Xvfb) for the window tests: its DISPLAY string. Without Xvfb the
    window tests skip, saying so; under CI=true they fail instead."""
    if shutil.which("Xvfb") is None:
        skip_or_fail(
            "no X server for the window tests: Xvfb is not installed (Debian package xvfb)"
        )
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen(
        [
            "Xvfb",
            "-displayfd",
            str(write_fd),
            "-screen",
            "0",
            f"{X_SCREEN[0]}x{X_SCREEN[1]}x24",
            "-nolisten",
            "tcp",
            "-br",
            "-noreset",
        ],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    # Xvfb writes the number, then "\n" in a second write: closing the pipe before the
    # newline arrives kills the server (EPIPE is fatal there).
    data = b""
    deadline = time.monotonic() + 30
    while not data.endswith(b"\n") and time.monotonic() < deadline:
        ready, _, _ = select.select([read_fd], [], [], 1.0)
        chunk = os.read(read_fd, 64) if ready else b""
        if ready and not chunk:
            break
        data += chunk
    os.close(read_fd)
    number = data.decode().strip()
    if not number:
        proc.kill()
        proc.wait(timeout=10)
        skip_or_fail("no X server for the window tests: Xvfb did not start within 30 s")
    yield f":{number}"
    proc.terminate()
    proc.wait(timeout=10)


def run_window_check(display: str, module: str) -> None:
    """Run a window check script on the X server in its own process (GLX and this
    process's EGL context do not mix); it prints 'keys ok' when every check passed."""
    r = subprocess.run(
        [sys.executable, "-m", module],
        capture_output=True,
        text=True,
        timeout=300,
        env=dict(os.environ, DISPLAY=display),
        cwd=REPO_ROOT,
    )
    assert r.returncode == 0 and r.stdout.strip().endswith("keys ok"), r.stdout + r.stderr


def run_cli(*args: str, timeout: float = 120, **kwargs) -> subprocess.CompletedProcess:
    """Run `sasprobe ARGS` as a user would (a real subprocess)."""
    env = dict(kwargs.pop("env", None) or os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run(
        [sys.executable, "-m", "sasprobe", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=kwargs.pop("cwd", REPO_ROOT),
        **kwargs,
    )
