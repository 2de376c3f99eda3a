"""The page in a real browser (headless Chromium, SwiftShader's WebGL2): the live page keeps up
with the daemon, its picture is the CPU ray caster's (the atom id of every pixel, away from
silhouettes), the HTML of a recording shows the recorded pose at the time it is seeked to and
plays offline, and without WebGL2 the page says so.

The reference picture is tests/render_support.py's brute-force numpy ray caster, with the
workspace view's camera worked out here from its definition (protocol/README.md, `view`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.conftest import run_cli
from tests.support.daemon_process import DaemonProcess
from tests.support.render import edge_mask, reference_cast
from tests.support.web import bridge_for, browser, drawing, picked_ids, wait_for

SIZE = (400, 300)
AGREE = 0.995  # of the pixels away from silhouettes


@pytest.fixture(scope="module")
def page():
    with browser(size=SIZE) as b:
        yield b


@pytest.fixture(scope="module")
def crambin_session(reference_by_id):
    with DaemonProcess("--molecule", str(reference_by_id["1crn"].path), device="sim:scan") as d:
        with bridge_for(d.pub, d.ctl) as bridge:
            yield d, bridge


def test_the_live_page_keeps_up_with_the_daemon(page, crambin_session):
    """After the daemon publishes a pose, the page draws it or a newer one."""
    from sasprobe.protocol.client import Subscriber

    daemon, bridge = crambin_session
    page.open(bridge.url)
    state = drawing(page)
    assert state["structure"] == "1crn" and state["atoms"] == 327
    with Subscriber(daemon.pub) as sub:
        for _ in range(5):
            wait_for(lambda: sub.poll(0.05) is not None and sub.pose, 30, "a pose from the daemon")
            published = sub.pose.seq
            page.wait(
                lambda p, s=published: p.state()["seq"] >= s, 60, f"the page draws {published}"
            )
    later = page.state()
    assert later["frames"] > state["frames"] and later["connected"]


def test_timed_draws_are_reported_once_asked_for_and_the_page_goes_on(page, crambin_session):
    """`timeDraws()`: the benchmark's draw times, none before it is called."""
    daemon, bridge = crambin_session
    page.open(bridge.url)
    before = drawing(page)
    assert before["draw_ms"] is None
    page.run("window.sasprobe.timeDraws()")
    state = page.wait(
        lambda p: (s := p.state())["frames"] >= before["frames"] + 5 and s, 120, "5 timed frames"
    )
    p50, p95 = state["draw_ms"]
    assert 0 < p50 <= p95, state["draw_ms"]


# ------------------------------------------------------------------ the picture
def workspace_camera(cube: dict, aspect: float):
    """Eye, forward, right and up of the workspace view: it looks along -(the cube's third
    axis) with the second up, from where a sphere of 1.5 half edges around the cube's centre,
    with 5 % to spare, fills the narrower field of view of 40 degrees vertical."""
    axes = np.asarray(cube["axes"], dtype=np.float64).reshape(3, 3)  # rows; columns are axes
    back, up = axes[:, 2], axes[:, 1]
    half = math.radians(40.0) / 2
    narrower = min(half, math.atan(math.tan(half) * aspect))
    distance = 1.5 * cube["half"] / math.sin(narrower) * 1.05
    eye = np.asarray(cube["center"]) + back * distance
    return eye, -back, np.cross(up, back), up


def view_projection(eye, forward, right, up, aspect: float, near: float, far: float):
    view = np.eye(4)
    view[:3, :3] = np.stack([right, up, -forward])
    view[:3, 3] = -view[:3, :3] @ eye
    f = 1 / math.tan(math.radians(40.0) / 2)
    proj = np.zeros((4, 4))
    proj[0, 0], proj[1, 1] = f / aspect, f
    proj[2, 2], proj[2, 3], proj[3, 2] = (
        (far + near) / (near - far),
        2 * far * near / (near - far),
        -1,
    )
    return view, proj


def cube_atoms(structure, cube: dict) -> np.ndarray:
    """The atoms whose sphere overlaps the cube (a sphere-box test in the cube's frame)."""
    axes = np.asarray(cube["axes"], dtype=np.float64).reshape(3, 3)
    q = (structure.positions - np.asarray(cube["center"])) @ axes
    gap = q - np.clip(q, -cube["half"], cube["half"])
    return np.flatnonzero(np.einsum("ij,ij->i", gap, gap) <= structure.vdw_radii**2)


def cube_faces(cube: dict) -> np.ndarray:
    """The cube's six faces as planes a x + b y + c z + d >= 0 that keep its inside."""
    axes = np.asarray(cube["axes"], dtype=np.float64).reshape(3, 3)
    c = np.asarray(cube["center"])
    planes = []
    for k in range(3):
        n = axes[:, k]
        planes += [[*n, -(n @ c) + cube["half"]], [*(-n), n @ c + cube["half"]]]
    return np.array(planes)


def reference_ids(structure, picked: dict) -> np.ndarray:
    w, h = picked["width"], picked["height"]
    cube, probe = picked["cube"], picked["probe"]
    eye, forward, right, up = workspace_camera(cube, w / h)
    np.testing.assert_allclose(picked["camera"]["eye"], eye, atol=1e-3)
    view, proj = view_projection(eye, forward, right, up, w / h, 0.1, 2000.0)
    atoms = cube_atoms(structure, cube)
    ids, pos, _, _ = reference_cast(
        view, proj, w, h, structure.positions[atoms], structure.vdw_radii[atoms], atoms,
        planes=cube_faces(cube),
    )  # fmt: skip
    probe_ids, probe_pos, _, _ = reference_cast(
        view, proj, w, h, np.array([probe["center"]]), np.array([probe["radius"]]), np.array([-2])
    )
    t_atoms = np.where(ids >= 0, np.linalg.norm(pos - eye, axis=-1), np.inf)
    t_probe = np.where(probe_ids == -2, np.linalg.norm(probe_pos - eye, axis=-1), np.inf)
    return np.where(t_probe < t_atoms, -2, ids)


@pytest.mark.parametrize("entry", ["1crn", "1aon"])
def test_the_atom_under_every_pixel_is_the_ray_casters(page, reference_by_id, entry):
    from sasprobe.molecule import load_structure

    path = reference_by_id[entry].path
    structure = load_structure(path)
    with DaemonProcess("--molecule", str(path), device="sim:scan") as daemon:
        with bridge_for(daemon.pub, daemon.ctl) as bridge:
            page.open(bridge.url)
            drawing(page, frames=3, timeout_s=180)
            picked = page.run("return window.sasprobe.pick()")
    assert picked["cube"] is not None and (picked["width"], picked["height"]) == SIZE
    got = picked_ids(picked)
    want = reference_ids(structure, picked)
    away = ~edge_mask(want)
    atoms = want >= 0
    assert atoms.mean() > 0.05, "the picture shows atoms"
    agree = (got == want)[away].mean()
    assert agree >= AGREE, (
        f"{entry}: {agree:.4f} of {away.sum()} pixels agree; "
        f"{np.unique(got[away & (got != want)]).size} ids differ"
    )


# ------------------------------------------------------------------ the HTML of a recording
@pytest.fixture(scope="module")
def recording_html(reference_by_id, tmp_path_factory):
    folder = tmp_path_factory.mktemp("web-replay")
    recording = folder / "session.mcap"
    with DaemonProcess(
        "--molecule",
        str(reference_by_id["1crn"].path),
        "--record",
        str(recording),
        "--seconds",
        "4",
        "--inject-button",
        "2@1500+20",  # a mark at 1.5 s
        device="sim:scan",
    ) as d:
        d.proc.wait(timeout=120)  # it stops by itself after 4 s
    html = folder / "session.html"
    r = run_cli("replay", str(recording), "--html", str(html), timeout=300)
    assert r.returncode == 0, r.stderr
    return recording, html


def recorded_poses(recording):
    """(log time ns, seq, proxy) of every recorded pose, read straight from the file as the
    README's tables lay it out."""
    from tests.support.recordings import reference_ticks

    return [
        (t["pose"]["publish_t_ns"], t["pose"]["seq"], t["pose"]["proxy"])
        for t in reference_ticks(recording)
    ]


def test_the_html_shows_the_recorded_pose_at_the_time_it_is_seeked_to(page, recording_html):
    recording, html = recording_html
    poses = recorded_poses(recording)
    t0 = poses[0][0]
    page.open(html.as_uri())
    page.wait(lambda p: (s := p.state()) and s.get("loaded") and s["frames"] > 0, 120, "loaded")
    duration = page.state()["duration_s"]  # the last frame's moment
    assert abs(duration - math.floor((poses[-1][0] - t0) / 1e9 * 60) / 60) < 1e-6
    for t in (0.5, 1.25, 2.0 + 1 / 120, duration):
        moment = t0 + math.floor(t * 60 + 1e-9) / 60 * 1e9  # frames every 1/60 s
        log_time, seq, proxy = [p for p in poses if p[0] <= moment][-1]
        assert (t * 1e9 + t0 - log_time) / 1e9 < 1 / 60 + 0.01  # the pose shown is that recent
        page.run("window.sasprobe.seek(arguments[0])", t)
        page.wait(lambda p, s=seq: p.state()["seq"] == s, 30, f"the page shows pose {seq} at {t} s")
        picked = page.run("return window.sasprobe.pick()")
        assert picked["seq"] == seq
        np.testing.assert_allclose(picked["probe"]["center"], proxy, atol=1e-4)


def test_the_html_plays_offline_with_its_marks(page, recording_html):
    _, html = recording_html
    page.open(html.as_uri())
    page.wait(lambda p: (s := p.state()) and s.get("loaded") and s["frames"] > 0, 120, "loaded")
    page.run("window.sasprobe.seek(0); window.sasprobe.play()")
    page.wait(lambda p: p.state()["time_s"] > 0.3, 60, "the session plays")
    first = page.state()
    page.wait(lambda p: p.state()["seq"] > first["seq"], 60, "later poses are drawn")
    page.run("window.sasprobe.pause()")
    assert not page.state()["playing"]
    ticks = page.run("return [...document.querySelectorAll('.timeline .tick')].map(e => e.title)")
    assert ticks and all(t.startswith("mark") for t in ticks)
    fetched = page.run(
        "return performance.getEntriesByType('resource').map(e => e.name)"
        ".filter(n => !n.startsWith('data:'))"
    )
    assert fetched == [], fetched


def test_without_webgl2_the_page_says_so_in_one_line(recording_html):
    _, html = recording_html
    with browser(size=SIZE, flags=("--disable-webgl", "--disable-webgl2")) as b:
        b.open(html.as_uri())
        text = b.wait(
            lambda p: p.run(
                "const e = document.querySelector('.status.fatal'); return e && e.textContent"
            ),
            60,
            "the page explains",
        )
    assert text == "This page needs WebGL2, which this browser does not offer."
