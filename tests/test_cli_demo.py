"""`sasprobe demo` end to end through the real CLI: daemon and renderer as real processes.

The video is read back with imageio's ffmpeg reader; the snapshot (the whole molecule in
the cube, `--cube-half fit`, seen in the overview) is compared with an independent numpy
ray cast of the same structure from the same fitted camera (the renderer fits its
camera to the structure alone); the haptic rate is the daemon's own
measurement; the recording is replayed (forces recomputed, exactly) and rendered to a
video whose frame count and timing are checked against the recording read with the
`mcap` library directly; and a Ctrl+C (SIGINT) mid-run must leave no process of the
demo's tree behind and the simulated arm's last force at zero.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import REPO_ROOT, run_cli
from tests.support.recordings import reference_ticks
from tests.support.render import edge_mask, reference_cast

pytestmark = pytest.mark.timeout(600)  # a daemon and a renderer each start in minutes when busy

SECONDS = 3
FPS = 10  # the demo's default headless frame rate
SIZE = (640, 360)  # and size
BACKGROUND = np.array([0.08, 0.09, 0.11]) * 255  # ShadingSettings().background


def cpu_times() -> tuple[int, int] | None:
    """(steal, total) CPU time of the whole machine so far, in clock ticks, from the kernel's
    /proc/stat; None where it is not told. Steal is time a hypervisor gave this machine's
    CPUs to others: no scheduling policy inside the machine gets it back."""
    try:
        with open("/proc/stat") as f:
            fields = [int(v) for v in f.readline().split()[1:9]]  # user … steal
    except (OSError, ValueError):
        return None
    return (fields[7], sum(fields)) if len(fields) == 8 else None


@pytest.fixture(scope="module")
def demo(tmp_path_factory, gl):  # gl: skips where no headless OpenGL exists
    """(out folder, the CLI's result, the machine's (steal, all) CPU ticks before and after or
    None)."""
    out = tmp_path_factory.mktemp("demo")
    before = cpu_times()
    # The whole of crambin in the cube, seen whole (the overview), so that the snapshot can be
    # checked against a ray cast of every atom, without the readout's box over its corner
    # (tests/test_render_readout.py); the workspace view is
    # tests/test_devices_workspace_session.py's.
    result = run_cli(
        "demo",
        "--headless",
        "--seconds",
        str(SECONDS),
        "--out",
        str(out),
        "--record",
        str(out / "session.mcap"),
        "--daemon-args=--cube-half fit",
        "--render-args=--view overview --no-readout",
        timeout=300,
    )
    after = cpu_times()
    assert result.returncode == 0, result.stderr
    return out, result, (before, after) if before and after else None


def test_demo_writes_a_playable_video_of_the_requested_length(demo):
    import imageio.v2 as imageio

    out, result, _ = demo
    assert str(out / "demo.mp4") in result.stdout and str(out / "summary.json") in result.stdout
    summary = json.loads((out / "summary.json").read_text())
    reader = imageio.get_reader(out / "demo.mp4")
    try:
        frames = [frame for frame in reader]
        meta = reader.get_meta_data()
    finally:
        reader.close()
    # Paced to wall-clock time: one frame per 1/fps of the --seconds, late frames repeated.
    assert len(frames) == SECONDS * FPS == summary["renderer"]["video_frames"]
    assert meta["fps"] == FPS and tuple(meta["size"]) == SIZE
    assert all(f.shape == (SIZE[1], SIZE[0], 3) for f in frames)
    assert summary["renderer"]["frames"] >= 2, "the renderer should draw while the arm moves"
    moving = [np.abs(a.astype(int) - b.astype(int)).max() for a, b in zip(frames, frames[1:])]
    assert max(moving) > 30, "the probe should move between video frames"


def test_snapshot_shows_the_molecule(demo):
    import imageio.v2 as imageio
    from sasprobe.molecule import load_default
    from sasprobe.render.camera import Camera
    from sasprobe.render.scene_state import SceneState

    out, _, _ = demo
    image = imageio.imread(out / "snapshot.png")[..., :3].astype(float)
    assert image.shape == (SIZE[1], SIZE[0], 3)
    structure = load_default()
    camera = Camera.framing(
        structure.positions, structure.vdw_radii, SIZE[0] / SIZE[1]
    )  # the renderer's fitted view
    center, radius = SceneState(structure).bounding_sphere()
    camera.fit_clip_range(center, radius)
    ids, _, _, _ = reference_cast(
        camera.view(),
        camera.projection(SIZE[0] / SIZE[1]),
        SIZE[0],
        SIZE[1],
        structure.positions,
        structure.vdw_radii,
        np.arange(structure.n_atoms),
    )
    # Shadows and ambient occlusion darken atoms, never to the background colour itself.
    drawn = np.linalg.norm(image - BACKGROUND, axis=-1) > 3
    atoms = ids >= 0
    inner = ~edge_mask(ids)
    assert atoms.mean() > 0.1, "the reference itself should cover a good part of the frame"
    # The atom pixels of the reference are drawn (the probe and the cube wire add a few more).
    assert drawn[atoms & inner].mean() > 0.98
    assert (drawn & ~atoms & inner).mean() < 0.05
    # ... in the atoms' CPK colours: oxygen pixels red-dominated, nitrogen blue, carbon grey.
    elements = structure.elements[np.where(atoms & inner, ids, 0)]
    for element, check in (
        ("O", lambda c: c[0] > 1.5 * c[2]),
        ("N", lambda c: c[2] > 1.5 * c[0]),
        ("C", lambda c: np.ptp(c) < 0.2 * c.mean()),
    ):
        pixels = image[atoms & inner & (elements == element)]
        assert len(pixels) > 500 and check(np.median(pixels, axis=0)), element


def test_summary_reports_the_haptic_rate_forces_and_a_clean_stop(demo):
    out, result, cpu = demo
    s = json.loads((out / "summary.json").read_text())
    h = s["haptics"]
    assert h["nominal_rate_hz"] == 1000.0 and h["window_s"] >= SECONDS
    # The loop keeps its 1 kHz schedule and counts every deadline it misses: the ticks it ran
    # and the deadlines it missed fill the window.
    assert h["ticks"] + h["missed_deadlines"] == pytest.approx(h["window_s"] * 1000, rel=0.01), h
    assert h["rate_hz"] == pytest.approx(h["ticks"] / h["window_s"], rel=1e-3), h
    # How many it misses depends on the machine. A SCHED_FIFO loop keeps 1 kHz against other
    # processes, not against a hypervisor that takes the CPUs away (a virtual machine's
    # steal). On one 2-core VM, three demos with 0.1-0.7 % stolen ran at 990-998 Hz, and
    # with 3.0, 4.5 and 6.5 % stolen at 971, 949 and 922 Hz. So the rate is held to 5 %
    # wherever the hypervisor took less than 2 %.
    if cpu is not None:
        (steal_0, all_0), (steal_1, all_1) = cpu
        stolen = (steal_1 - steal_0) / (all_1 - all_0)
        if stolen < 0.02:
            assert abs(h["rate_hz"] - h["nominal_rate_hz"]) <= 0.05 * h["nominal_rate_hz"], (
                h,
                stolen,
            )
        # The summary tells the steal over its window, which lies inside this test's: no more
        # CPU-seconds than this test counted; the closing lines name it from 1 %.
        told = h["cpu_steal"]
        assert (
            0 <= told["seconds"] <= (steal_1 - steal_0) / os.sysconf("SC_CLK_TCK")
            and 0 <= told["percent"] <= 100
        )
        assert ("the hypervisor took" in result.stdout) == (told["percent"] >= 1.0), result.stdout
    f = s["forces"]
    assert f["poses"] >= 0.9 * h["ticks"]  # the demo's own subscriber saw nearly every tick
    assert f["contact_ticks"] > 0 and f["atoms_touched"] > 0, (
        "the scan script presses on the surface"
    )
    assert 0 < f["force_n"]["max"] <= 3.3 + 1e-9  # the simulated Omni's force limit
    r = s["renderer"]
    assert (
        r["daemon"]["poses_received"] > 0
        and r["daemon"]["poses_missed"] == 0
        and r["daemon"]["malformed"] == 0
    )
    d = s["daemon_exit"]
    assert d["reason"] == "SIGTERM" and d["device_last_force_n"] == [0.0, 0.0, 0.0]
    assert s["structure"]["name"] == "1crn" and s["structure"]["n_atoms"] == 327


def test_recorded_demo_replays_to_video_with_identical_forces(demo, tmp_path):
    import imageio.v2 as imageio

    out, _, _ = demo
    fps = 8
    result = run_cli(
        "replay",
        str(out / "session.mcap"),
        "--verify",
        "--video",
        str(tmp_path / "replay.mp4"),
        "--fps",
        str(fps),
        "--size",
        "160x96",
        "--json",
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["verify"]["ok"] and report["verify"]["max_force_diff_n"] == 0.0
    assert report["verify"]["ticks"] > SECONDS * 900
    times = [t["pose"]["publish_t_ns"] for t in reference_ticks(out / "session.mcap")]
    expected = int((max(times) - min(times)) * fps // 1_000_000_000) + 1
    reader = imageio.get_reader(tmp_path / "replay.mp4")
    try:
        frames = [frame for frame in reader]
        assert reader.get_meta_data()["fps"] == fps
    finally:
        reader.close()
    assert len(frames) == expected == report["video"]["frames"]
    assert frames[0].shape == (96, 160, 3)
    assert max(np.abs(a.astype(int) - b.astype(int)).max() for a, b in zip(frames, frames[1:])) > 30


def test_replay_frames_follow_the_recorded_timing(demo):
    """Frame k shows the newest pose published at or before first + k/fps (the recording read
    independently: the mcap library and the README's tables)."""
    from sasprobe.protocol.playback import recorded_frames

    out, _, _ = demo
    fps = 25.0
    poses = sorted(
        (t["pose"]["publish_t_ns"], t["pose"]["seq"]) for t in reference_ticks(out / "session.mcap")
    )
    times = np.array([t for t, _ in poses])
    seqs = np.array([s for _, s in poses])
    frames = list(recorded_frames(out / "session.mcap", fps))
    assert len(frames) == int((times[-1] - times[0]) * fps // 1e9) + 1
    for frame in frames:
        t = times[0] + frame.index * 1e9 / fps
        assert frame.pose.seq == seqs[np.searchsorted(times, t, side="right") - 1]


def test_with_a_display_the_demo_opens_a_window(xvfb, tmp_path):
    """Under a real X server (Xvfb) the renderer is a window that follows the daemon. The
    window stays open for a time (the demo sets it no frame count), long enough for a software
    renderer on a busy machine to draw three frames."""
    out = tmp_path / "window"
    result = run_cli(
        "demo",
        "--seconds",
        "10",
        "--size",
        "320x240",
        "--out",
        str(out),
        timeout=300,
        env=dict(os.environ, DISPLAY=xvfb),
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mode"] == "window" and not summary["notes"]
    assert summary["renderer"]["window"] is True and summary["renderer"]["frames"] >= 3
    assert summary["renderer"]["daemon"]["poses_received"] > 0
    assert summary["daemon_exit"]["device_last_force_n"] == [0.0, 0.0, 0.0]
    assert not (out / "demo.mp4").exists()


def _descendants(pid: int) -> dict[int, str]:
    """Every process below pid (from /proc), as pid -> start time (to tell a reused pid apart)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            stat = _stat(int(entry))
            if stat is not None:
                children.setdefault(int(stat[1]), []).append(int(entry))
    found, todo = {}, [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            stat = _stat(child)
            if stat is not None:
                found[child] = stat[19]
                todo.append(child)
    return found


def _stat(pid: int) -> list[str] | None:
    """/proc/PID/stat fields after the command name: state, ppid, ..., starttime at index 19."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return text[text.rindex(")") + 2 :].split()


def _running(pid: int, start_time: str) -> bool:
    stat = _stat(pid)
    return stat is not None and stat[19] == start_time and stat[0] not in ("Z", "X")


@pytest.mark.parametrize("inherited", ["default", "ignored"])
def test_sigint_stops_every_process_and_leaves_the_arm_at_zero_force(tmp_path, gl, inherited):
    """SIGINT mid-run stops the demo, its daemon and its renderer, the force at zero and the
    video finished — also when the demo was started with SIGINT ignored, as a script's
    background job is."""
    out = tmp_path / "demo"
    argv = [
        sys.executable,
        "-m",
        "sasprobe",
        "demo",
        "--headless",
        "--seconds",
        "120",
        "--out",
        str(out),
    ]
    if (
        inherited == "ignored"
    ):  # ignored, then exec'd: the demo starts with SIGINT ignored, in the same process
        argv = [
            sys.executable,
            "-c",
            (
                "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); "
                f"os.execv(sys.executable, {argv!r})"
            ),
        ]
    proc = subprocess.Popen(
        argv,
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    try:
        deadline = time.monotonic() + 120
        tree: dict[int, str] = {}
        # Mid-run: the video has frames and the tree is complete (daemon, renderer, its encoder).
        while time.monotonic() < deadline and proc.poll() is None:
            tree.update(_descendants(proc.pid))
            video = out / "demo.mp4"
            if len(tree) >= 3 and video.exists() and video.stat().st_size > 0:
                break
            time.sleep(0.2)
        assert proc.poll() is None, proc.communicate(timeout=30)[1]
        time.sleep(1.0)
        tree.update(_descendants(proc.pid))
        assert len(tree) >= 3, f"expected daemon, renderer and encoder below the demo, found {tree}"
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=30)
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr
    left = [pid for pid, start in tree.items() if _running(pid, start)]
    assert not left, f"processes left behind: {left}"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True
    exit_report = summary["daemon_exit"]
    assert exit_report["reason"] == "SIGTERM"
    assert exit_report["last_force_written_n"] == [0.0, 0.0, 0.0]
    assert exit_report["device_last_force_n"] == [0.0, 0.0, 0.0]
    # The renderer finished its video on the way out: a readable file with the frames so far.
    import imageio.v2 as imageio

    reader = imageio.get_reader(out / "demo.mp4")
    try:
        assert reader.count_frames() == summary["renderer"]["video_frames"] >= 1
    finally:
        reader.close()


def test_a_child_that_ignores_signals_is_killed_with_its_own_children(tmp_path):
    """The last resort: a hung child (SIGTERM ignored) and the process it started both go."""
    from sasprobe.cli.children import Child

    code = (
        "import signal, subprocess, sys, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
        "g = subprocess.Popen([sys.executable, '-c', 'import signal, time; "
        "signal.signal(signal.SIGTERM, signal.SIG_IGN); time.sleep(60)']); "
        'print(\'{"event": "ready", "grandchild": %d}\' % g.pid, flush=True); time.sleep(60)'
    )
    child = Child("hung", [sys.executable, "-c", code], tmp_path / "hung.log")
    ready = child.wait_event("ready", 30)
    assert ready is not None
    grandchild = ready["grandchild"]
    start = _stat(grandchild)[19]
    child.signal(signal.SIGTERM)
    t0 = time.monotonic()
    rc = child.finish(timeout_s=1.0)
    assert rc == -signal.SIGKILL and time.monotonic() - t0 < 10
    deadline = time.monotonic() + 5
    while _running(grandchild, start) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _running(grandchild, start)
