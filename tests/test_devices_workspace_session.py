"""The haptic session through the real CLI, headless: the demo on 1CRN, 1AON and 6ZU5 (every
frame's G-buffer), the view's turn against the hand's motion, the clutch and recentre
(recorded and replayed exactly), `sasprobe set`, a daemon restart under a connected
renderer, and a renderer whose daemon dies.

The geometry checks are the tests' own: pixels from the G-buffer's view and projection
(OpenGL conventions, row 0 at the top), the cube's projected outline as the convex hull of
its projected corners, the probe's on-screen centre as the mean of its pixels. The
renderer runs without shadows and AO here (`--ao off --shadows off`): what is checked is
where things are drawn, and the lighting's set-up for 165k atoms would cost seconds.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from sasprobe.protocol.client import ControlClient, Subscriber
from sasprobe.protocol.pose import FLAG_CLUTCHED, FLAG_FAULT

from tests.conftest import REPO_ROOT, run_cli, run_window_check
from tests.support.daemon_process import DaemonProcess, free_tcp_endpoint

pytestmark = pytest.mark.timeout(600)  # a demo on 6ZU5 per module, a daemon and a renderer each

SECONDS = 5
SIZE = (640, 360)
# The readout's text box lies over the picture's top-left corner (tests/test_render_readout.py
# checks it); these checks look at the molecule and the cube beneath it.
FAST = "--ao off --shadows off --no-readout"
KIND_BACKBONE, KIND_PROBE = 3, 4  # the G-buffer's kinds (docs/viewing.md: G-buffer export)
WIRE = np.array([0.55, 0.85, 1.0]) * 255  # the cube wire's colour
TURN_Y = [
    [0.0, 0.0, -1.0],
    [0.0, 1.0, 0.0],
    [1.0, 0.0, 0.0],
]  # the view turned -90° about the screen's y


def to_pixels(points, view, proj, size) -> np.ndarray:
    """(N, 2) pixel coordinates (x right, y down, pixel centres at integers) of world points."""
    p = (
        np.concatenate([np.asarray(points, float), np.ones((len(points), 1))], axis=1)
        @ (proj @ view).T
    )
    ndc = p[:, :2] / p[:, 3:]
    return np.stack(
        [(ndc[:, 0] + 1) / 2 * size[0] - 0.5, (1 - ndc[:, 1]) / 2 * size[1] - 0.5], axis=1
    )


def cube_corners(cube, axes) -> np.ndarray:
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    return cube[:3] + cube[3] * signs @ np.asarray(axes).T


def cross2(a, b):
    """z of the cross product of 2-d vectors (arrays of them broadcast)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def hull(points: np.ndarray) -> np.ndarray:
    """Convex hull of 2-d points by the monotone chain."""
    pts = sorted(map(tuple, points))

    def half(seq):
        out = []
        for p in seq:
            while (
                len(out) >= 2
                and cross2(np.subtract(out[-1], out[-2]), np.subtract(p, out[-2])) <= 0
            ):
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def inside_by(polygon: np.ndarray, size, margin: float) -> np.ndarray:
    """Pixels whose centre lies inside a convex polygon by at least `margin` pixels."""
    ys, xs = np.mgrid[0 : size[1], 0 : size[0]]
    pix = np.stack([xs, ys], axis=-1).astype(float)
    inside = np.ones(ys.shape, bool)
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
        edge = b - a
        dist = cross2(edge, pix - a) / np.linalg.norm(edge)  # signed distance to the edge's line
        inside &= dist * np.sign(cross2(polygon[1] - polygon[0], polygon[2] - polygon[0])) >= margin
    return inside


# ------------------------------------------------------------------ the demo on three structures
@pytest.fixture(scope="module", params=["1crn", "1aon", "6zu5"])
def demo(request, reference_by_id, tmp_path_factory, gl):
    out = tmp_path_factory.mktemp(f"demo_{request.param}")
    frames = out / "g"
    result = run_cli(
        "demo",
        "--headless",
        "--seconds",
        str(SECONDS),
        "--molecule",
        str(reference_by_id[request.param].path),
        "--out",
        str(out),
        f"--render-args=--gbuffer-dir {frames} {FAST}",
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    keep = ("kind", "view", "proj", "nav_cube", "nav_cube_axes")
    gbuffers = []
    for path in sorted(
        frames.glob("gbuffer_*.npz")
    ):  # read what the checks need, then free the disk
        with np.load(path) as g:
            gbuffers.append({k: g[k] for k in keep})
        path.unlink()
    summary = json.loads((out / "summary.json").read_text())
    import imageio.v2 as imageio

    return (
        request.param,
        gbuffers,
        summary,
        imageio.imread(out / "snapshot.png")[..., :3].astype(float),
    )


def in_workspace_view(g) -> bool:
    """The frame looks along the cube's z axis (the demo opens on an overview from 60° above
    it, where the probe of a large complex is a few pixels: tests/test_render_readout.py)."""
    forward = g["view"][2, :3] / np.linalg.norm(g["view"][2, :3])
    return abs(float(forward @ g["nav_cube_axes"][:, 2])) > 0.9


def test_demo_draws_the_probe_large_in_every_frame(demo):
    name, gbuffers, summary, _ = demo
    assert len(gbuffers) == summary["renderer"]["frames"] >= 2, (
        "the renderer should draw while the arm moves"
    )
    workspace = [g for g in gbuffers if in_workspace_view(g)]
    assert len(workspace) >= len(gbuffers) / 2, (name, len(workspace), len(gbuffers))
    probe = [int((g["kind"] == KIND_PROBE).sum()) for g in workspace]
    assert min(probe) >= 200, (name, probe)


def test_demo_trace_surrounds_the_cube_and_never_covers_it(demo):
    name, gbuffers, _, _ = demo
    for g in gbuffers:
        corners = to_pixels(
            cube_corners(g["nav_cube"], g["nav_cube_axes"]), g["view"], g["proj"], SIZE
        )
        interior = inside_by(hull(corners), SIZE, margin=1.0)  # a pixel clear of the outline's edge
        trace = g["kind"] == KIND_BACKBONE
        assert trace[~interior].sum() > 100, name  # the rest of the molecule, around the cube
        assert trace[interior].sum() == 0, name


def test_demo_cube_wire_is_visible(demo):
    """Along the cube's front face (toward the viewer: nothing but the probe's cues in front of it)
    the snapshot shows the wire's colour within a pixel of nearly every sampled point."""
    name, gbuffers, _, image = demo
    g = gbuffers[-1]  # the snapshot is the last frame
    c, axes = g["nav_cube"], g["nav_cube_axes"]
    front = [
        c[:3] + c[3] * (axes @ np.array([sx, sy, 1.0]))
        for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
    ]
    samples = [
        a + t * (b - a)
        for a, b in zip(front, front[1:] + front[:1])
        for t in np.linspace(0.1, 0.9, 9)
    ]
    seen = 0
    for x, y in to_pixels(samples, g["view"], g["proj"], SIZE):
        x, y = int(round(x)), int(round(y))
        window = image[max(y - 1, 0) : y + 2, max(x - 1, 0) : x + 2].reshape(-1, 3)
        seen += bool(np.any(np.linalg.norm(window - WIRE, axis=1) < 60))
    assert seen >= 0.9 * len(samples), (name, seen, len(samples))


def test_demo_touches_the_surface_at_once_within_the_ratings(demo):
    name, _, summary, _ = demo
    f = summary["forces"]
    assert f["first_touch_s"] is not None and f["first_touch_s"] <= 3.0, (name, f["first_touch_s"])
    assert f["continuous_force_n"] == 0.88 and f["clamped_ticks"] == 0
    assert f["above_continuous_s"] is not None and f["above_continuous_s"] <= 0.01, (name, f)
    assert f["atoms_touched"] > 0 and f["contact_fraction"] > 0.2


# ------------------------------------------------------------------ hand and eye aligned
def test_after_turning_the_view_the_probe_moves_on_screen_as_the_hand_does(tmp_path, gl):
    """The view turned -90° about the screen's y axis; the simulated hand then sweeps along the
    device's x and y (sim:sweep): hand +x moves the drawn probe right, hand +y moves it up."""
    with DaemonProcess("--seconds", "120", device="sim:sweep") as daemon:
        with ControlClient(daemon.ctl) as ctl:
            ctl.call("view", rotation=TURN_Y)
            assert np.allclose(ctl.get_scene()["view"]["rotation"], TURN_Y)
        frames = tmp_path / "g"
        # a paced video keeps the frames about 1/8 s apart (a G-buffer each), the hand ~2.5 mm apart
        result = run_cli(
            "render",
            "--connect",
            daemon.pub,
            "--control",
            daemon.ctl,
            "--headless",
            "--seconds",
            "5.5",
            "--out",
            str(tmp_path / "turned.mp4"),
            "--fps",
            "8",
            "--size",
            "320x180",
            "--gbuffer-dir",
            str(frames),
            *FAST.split(),
            timeout=300,
        )
        assert result.returncode == 0, result.stderr
    tips, centres = [], []
    for path in sorted(frames.glob("gbuffer_*.npz")):
        with np.load(path) as g:
            np.testing.assert_allclose(g["nav_cube_axes"], TURN_Y, atol=1e-9)
            rows, cols = np.nonzero(g["kind"] == KIND_PROBE)
            if rows.size < 20:
                continue
            tips.append(g["device_tip_mm"])
            centres.append([cols.mean(), rows.mean()])
    tips, centres = np.array(tips), np.array(centres)
    checked = {"x": 0, "y": 0}
    for (t0, t1), (c0, c1) in zip(
        zip(tips, tips[1:]), zip(centres, centres[1:])
    ):  # consecutive frames
        d, moved = t1 - t0, c1 - c0
        if d[0] > 1.5 and abs(d[1]) < 0.3 * d[0] and abs(d[2]) < 0.3 * d[0]:
            assert moved[0] > 1.0, (d, moved)  # hand right, probe right
            checked["x"] += 1
        if abs(d[1]) > 1.5 and abs(d[0]) < 0.3 * abs(d[1]) and abs(d[2]) < 0.3 * abs(d[1]):
            assert np.sign(moved[1]) == -np.sign(d[1]) and abs(moved[1]) > 1.0, (
                d,
                moved,
            )  # hand up, probe up
            checked["y"] += 1
    assert checked["x"] >= 1 and checked["y"] >= 1, (checked, np.round(tips, 1).tolist())


# ------------------------------------------------------------------ clutch, recentre, set; recorded
def test_clutch_recentre_and_set_are_applied_recorded_and_replay_exactly(tmp_path):
    record = tmp_path / "session.mcap"
    # the device's clutch button (0) held from tick 1000 for 700 ticks
    with DaemonProcess(
        "--seconds",
        "60",
        "--inject-button",
        "0@1000+700",
        "--record",
        str(record),
        device="sim:sweep",
    ) as daemon:
        sub = Subscriber(daemon.pub)
        poses = []

        def until(condition, timeout: float = 30.0) -> None:
            """Collect poses until condition(poses) holds (ticks, not wall time: a loaded machine
            loses ticks)."""
            end = time.monotonic() + timeout
            while not (poses and condition(poses)) and time.monotonic() < end:
                poses.extend(sub.poll(0.05))
            assert poses and condition(poses), "the daemon did not get there in time"

        with ControlClient(daemon.ctl) as ctl:
            until(lambda p: p[-1].seq >= 300)
            ctl.call("view", rotation=TURN_Y)
            until(lambda p: p[-1].seq >= 2000)
            key = ctl.call(
                "clutch", held=True
            )  # the window's key, never renewed: let go after its lease
            until(lambda p: p[-1].seq > key["seq"] + 100 and not p[-1].has(FLAG_CLUTCHED))
            recentre = ctl.call("recentre")
            until(lambda p: p[-1].seq >= recentre["seq"] + 300)
            r = run_cli(
                "set",
                "--ctl",
                daemon.ctl,
                "stiffness=0.2",
                "clip=0,0,1,-5",
                "probe-light=off",
                "cube-half=8",
            )
            assert r.returncode == 0, r.stderr
            scene = ctl.get_scene()
            until(lambda p: p[-1].seq >= recentre["seq"] + 600)
        sub.close()
        rc, report = daemon.stop()
    assert rc == 0 and report["last_force_written_n"] == [0.0, 0.0, 0.0]
    assert scene["haptics"]["stiffness_n_per_mm"] == 0.2 and scene["clip_planes"] == [
        [0.0, 0.0, 1.0, -5.0]
    ]
    assert scene["lights"]["probe"]["enabled"] is False
    by_seq = {p.seq: p for p in poses}
    seqs = np.array(sorted(by_seq))
    clutched = np.array([by_seq[s].has(FLAG_CLUTCHED) for s in seqs])
    button = [by_seq[s] for s in seqs if 1010 <= s < 1690]  # within the button's hold
    # (a tick whose device read failed, on a loaded machine, has no engine output to flag)
    assert button and all(p.has(FLAG_CLUTCHED) for p in button if not p.has(FLAG_FAULT))
    assert all(np.array_equal(p.proxy_A, button[0].proxy_A) and not p.force_N.any() for p in button)
    assert np.ptp([p.tip_mm[0] for p in button]) > 5.0, "the hand kept moving (sweep along x)"
    after = [by_seq[s] for s in seqs if 1710 <= s < 2000]
    assert after and not any(p.has(FLAG_CLUTCHED) for p in after)
    assert np.ptp([p.proxy_A[2] for p in after]) > 0.1, "released, the probe follows the hand again"
    key_held = seqs[clutched & (seqs >= key["seq"]) & (seqs < recentre["seq"])]
    lease = (
        by_seq[key_held[-1]].publish_t_ns - by_seq[key_held[0]].publish_t_ns
    ) / 1e9  # the daemon's clock
    assert 0.9 <= lease <= 1.1, lease
    at = by_seq.get(recentre["seq"])
    if at is not None:  # the cube is centred on the probe at the recentre tick
        np.testing.assert_allclose(at.cube_center_A, by_seq[recentre["seq"] - 1].proxy_A, atol=1e-9)
    verify = run_cli("replay", str(record), "--verify", "--json", timeout=300)
    assert verify.returncode == 0, verify.stderr
    v = json.loads(verify.stdout)["verify"]
    assert v["ok"] and v["max_force_diff_n"] == 0.0 and v["events_applied"] >= 6, v


def test_window_keys_turn_clutch_recentre_and_switch_views(xvfb):
    run_window_check(xvfb, "tests.window_scripts.workspace")


def test_clip_with_connect_is_refused_in_one_line():
    r = run_cli("render", "--connect", "--headless", "--clip", "0,0,1,0")
    assert (
        r.returncode == 2
        and len(r.stderr.strip().splitlines()) == 1
        and "sasprobe set clip=" in r.stderr
    )


# ------------------------------------------------------------------ the link
def test_readout_comes_back_after_a_daemon_restart_and_never_says_running_and_not(monkeypatch):
    import sasprobe.protocol.follow as follow_module
    from sasprobe.render.follow.daemon_source import DaemonSource

    pub, ctl = free_tcp_endpoint(), free_tcp_endpoint()
    link = DaemonSource(pub, ctl)
    try:
        with DaemonProcess("--seconds", "60", pub=pub, ctl=ctl) as first:
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline and (
                link.readout().haptic_hz is None or link.structure is None
            ):
                link.poll()
                link.take_new_structure()
                time.sleep(0.02)
            assert link.readout().haptic_hz is not None and link.structure is not None
            first.stop()
        while link.connected:
            link.poll()
            time.sleep(0.05)
        assert link.readout().status.startswith("waiting for daemon")
        monkeypatch.setattr(
            follow_module, "FETCH_TIMEOUT_S", 1e-4
        )  # every get_structure now times out
        link.structure = None  # and the link wants the structure again (as a new daemon's would)
        with DaemonProcess("--seconds", "60", pub=pub, ctl=ctl):
            back = None
            t0 = time.monotonic()
            while time.monotonic() - t0 < 10:
                link.poll()
                readout = link.readout()
                assert not (readout.haptic_hz is not None and "is it running" in readout.status), (
                    readout
                )
                if readout.haptic_hz is not None and back is None:
                    back = time.monotonic() - t0
                if (
                    back is not None
                    and "fetching" in readout.status
                    and time.monotonic() - t0 > 1.5
                ):
                    # poses flow, fetches keep timing out: the readout has said both for a while
                    break
                time.sleep(0.01)
            assert back is not None and back <= 2.0, back  # from the new daemon's ready line
            assert 500 < readout.haptic_hz < 1100, readout
            assert "fetching the structure" in readout.status, readout
    finally:
        link.close()


def test_headless_render_whose_daemon_dies_ends_in_one_line(tmp_path):
    daemon = DaemonProcess("--seconds", "60")
    frames = tmp_path / "g"
    render = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "sasprobe",
            "render",
            "--connect",
            daemon.pub,
            "--control",
            daemon.ctl,
            "--headless",
            "--seconds",
            "60",
            "--size",
            "160x90",
            "--gbuffer-dir",
            str(frames),
            *FAST.split(),
        ],
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not any(frames.glob("gbuffer_*.npz")) and time.monotonic() < deadline:
            time.sleep(0.1)
        daemon.stop(signal.SIGKILL)
        _, err = render.communicate(timeout=60)
    finally:
        if render.poll() is None:
            render.kill()
    assert render.returncode == 2, err
    assert (
        err.strip()
        .splitlines()[-1]
        .endswith("the daemon stopped sending (nothing for 3 s): ending the render")
    )
    assert "Traceback" not in err
