"""The C client of examples/c, written from protocol/README.md alone, against a live daemon:
it must read `status`, change the stiffness with `set`, and decode every pose exactly as the
daemon recorded it (its doubles are printed to read back bit for bit)."""

from __future__ import annotations

import re
import shutil
import subprocess
import warnings

import pytest
from sasprobe.protocol.client import ControlClient
from sasprobe.protocol.schemas import pose_layout

from tests.conftest import REPO_ROOT, skip_or_fail
from tests.support.daemon_process import DaemonProcess
from tests.support.recordings import reference_ticks

SOURCE = REPO_ROOT / "examples" / "c" / "sasprobe_follow.c"
POSES = 300


@pytest.fixture(scope="module")
def client_binary(tmp_path_factory):
    """Built as docs/clients.md says, `make -C examples/c`, on a copy (nothing is written into
    the checkout). The Makefile asks for -Wall -Wextra but not -Werror: a compiler newer than
    the code may warn, and the build must still succeed (its warnings are reported, not failed)."""
    tools = [shutil.which(t) for t in ("cc", "make", "pkg-config")]
    flags = subprocess.run(["pkg-config", "--exists", "libzmq"], timeout=60) if all(tools) else None
    if flags is None or flags.returncode != 0:
        skip_or_fail(
            "no C toolchain with libzmq for examples/c (Debian: gcc, make, pkg-config, libzmq3-dev)"
        )
    folder = tmp_path_factory.mktemp("c")
    for name in ("Makefile", SOURCE.name):
        shutil.copy(SOURCE.parent / name, folder / name)
    build = subprocess.run(["make", "-C", str(folder)], capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stdout + build.stderr
    if "warning:" in build.stderr:
        warnings.warn(f"examples/c builds with warnings:\n{build.stderr}", stacklevel=1)
    return folder / "sasprobe_follow"


def _fields(line: str) -> dict:
    kind, *pairs = line.split(" ")
    return {"kind": kind, **dict(pair.split("=", 1) for pair in pairs)}


@pytest.mark.parametrize("transport", ["ipc", "tcp"])
def test_the_c_client_follows_a_daemon_and_changes_its_stiffness(
    client_binary, tmp_path, transport
):
    """ipc://, and loopback TCP with CURVE and the user's local keys."""
    path = tmp_path / "c.mcap"
    sockets, keys = {}, []
    if transport == "tcp":
        from sasprobe.protocol.security import local_keys_dir

        from tests.support.daemon_process import free_port

        sockets = {
            "pub": f"tcp://127.0.0.1:{free_port()}",
            "ctl": f"tcp://127.0.0.1:{free_port()}",
        }
    with DaemonProcess("--record", str(path), **sockets) as d:
        if transport == "tcp":
            keys = [
                "--keys",
                str(local_keys_dir()),
            ]  # made by the daemon on loopback, if not there yet
        run = subprocess.run(
            [
                str(client_binary),
                "--pub",
                d.pub,
                "--ctl",
                d.ctl,
                "--poses",
                str(POSES),
                "--stiffness",
                "0.2",
                *keys,
            ],
            capture_output=True,
            text=True,
            timeout=120,
        )
        with ControlClient(d.ctl) as client:
            scene = client.get_scene()
        d.stop()
    assert run.returncode == 0, run.stderr
    lines = [_fields(line) for line in run.stdout.splitlines()]
    kinds = [line["kind"] for line in lines]
    assert kinds[0] == "status" and float(lines[0]["rate_hz"]) > 0 and lines[0]["n_atoms"] == "327"
    assert kinds[1] == "set" and scene["haptics"]["stiffness_n_per_mm"] == 0.2
    assert kinds.count("pose") == POSES and kinds[-1] == "done" and "scene" in kinds
    assert any(line["kind"] == "scene" and line["stiffness_n_per_mm"] == "0.2" for line in lines)
    record_name = {f["name"]: f["record"] for f in pose_layout()["fields"] if f["record"]}
    recorded = {
        t["pose"]["seq"]: {
            record_name[k]: list(v) if isinstance(v, tuple) else v
            for k, v in t["pose"].items()
            if k in record_name
        }
        for t in reference_ticks(path)
    }
    names = {
        "proxy": "proxy_A",
        "goal": "goal_A",
        "force": "force_N",
        "tip": "tip_mm",
        "orientation": "orientation",
        "cube_center": "cube_center_A",
    }
    for line in (x for x in lines if x["kind"] == "pose"):
        want = recorded[int(line["seq"])]
        for key in ("flags", "buttons", "device_t_ns", "publish_t_ns", "touched_atom"):
            assert int(line[key]) == want[key], (key, line, want)
        for key, record in names.items():
            assert [float(v) for v in line[key].split(",")] == want[record], (key, line, want)
        assert float(line["cube_half"]) == want["cube_half_A"]


def test_what_the_makefile_builds_is_ignored_by_git():
    """`make -C examples/c` writes its target beside the source; .gitignore keeps it out."""
    makefile = (SOURCE.parent / "Makefile").read_text()
    rules = [
        line.split(":", 1)[0]
        for line in makefile.splitlines()  # `target: prerequisites` lines
        if re.match(r"[\w.]+:(?!=)", line)
    ]
    targets = [rule for rule in rules if rule != "clean"]
    ignored = (REPO_ROOT / ".gitignore").read_text().splitlines()
    assert targets and all(f"/examples/c/{target}" in ignored for target in targets), targets
