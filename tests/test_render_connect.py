"""`--connect`: the renderer follows a real daemon (simulated arm, real ZeroMQ sockets).

The rendered probe must sit exactly where the pose stream puts it (the probe centre
recovered from the G-buffer's probe pixels, each at position - radius * normal, against
the proxy of the pose with the same sequence number as seen by an independent
subscriber); malformed messages are dropped and counted; no daemon gives one line.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pytest
import zmq
from sasprobe.protocol.client import ControlClient, Subscriber
from sasprobe.protocol.pose import FLAG_CONTACT, Pose, encode_pose
from sasprobe.protocol.scene import encode_scene
from sasprobe.protocol.security import ensure_local_keys, load_server_keys, make_curve_server
from sasprobe.render.camera import Camera
from sasprobe.render.follow.daemon_source import DaemonSource
from sasprobe.render.gbuffer_export import gbuffer_arrays
from sasprobe.render.gl.targets import KIND_PROBE
from sasprobe.render.lighting.settings import AOSettings
from sasprobe.render.renderer import Renderer
from sasprobe.render.scene_state import Effects, SceneState

from tests.conftest import run_cli
from tests.support.daemon_process import DaemonProcess, free_tcp_endpoint

ORBIT = "sim:orbit"  # the simulated arm circling the molecule: the probe keeps moving


@pytest.fixture(scope="module")
def daemon():
    with DaemonProcess(
        "--seconds", "600", device=ORBIT, pub=free_tcp_endpoint(), ctl=free_tcp_endpoint()
    ) as d:
        yield d.pub, d.ctl
        d.stop(signal.SIGINT)


def test_rendered_probe_follows_the_pose_stream(gl, daemon):
    pub, ctl = daemon
    watch = Subscriber(pub)  # an independent record of every pose, by sequence number
    link = DaemonSource(pub, ctl)
    proxies: dict[int, np.ndarray] = {}
    renderer = None
    try:
        deadline = time.monotonic() + 60
        structure = None
        while structure is None and time.monotonic() < deadline:
            link.poll()
            structure = link.take_new_structure()
            time.sleep(0.02)
        assert structure is not None and structure.n_atoms == 327, "no structure from get_structure"
        scene = SceneState(
            structure, effects=Effects(probe_plane=True)
        )  # nothing may hide the probe
        center, radius = scene.bounding_sphere()
        camera = Camera.fitted(center, radius * 1.3, 4 / 3)
        renderer = Renderer(gl, scene, (160, 120))
        checked, positions = 0, set()
        while (checked < 8 or len(positions) < 3) and time.monotonic() < deadline:
            link.poll()
            link.apply(scene)
            pose = link.subscriber.pose
            if pose is None:
                continue
            renderer.render(camera)
            g = gbuffer_arrays(renderer)
            for p in watch.poll():
                proxies[p.seq] = p.proxy_A
            while pose.seq not in proxies and time.monotonic() < deadline:
                proxies.update({p.seq: p.proxy_A for p in watch.poll(0.05)})
            probe = g["kind"] == KIND_PROBE
            if probe.sum() < 20:
                continue  # out of view this frame
            rendered = (g["position"][probe] - scene.probe.radius * g["normal"][probe]).mean(axis=0)
            np.testing.assert_allclose(rendered, proxies[pose.seq], atol=2e-3)
            np.testing.assert_allclose(
                g["nav_cube"], [*pose.cube_center_A, pose.cube_half_A], atol=1e-9
            )
            checked += 1
            positions.add(tuple(np.round(proxies[pose.seq], 1)))
        assert checked >= 8, f"only {checked} frames showed the probe"
        assert len(positions) >= 3, "the simulated arm should move the probe between frames"
        assert link.readout().haptic_hz > 100
    finally:
        if renderer is not None:
            renderer.release()
        watch.close()
        link.close()


def test_cli_follows_the_daemon_headless(daemon, tmp_path):
    pub, ctl = daemon
    npz = tmp_path / "g.npz"
    r = run_cli(
        "render",
        "--headless",
        "--connect",
        pub,
        "--control",
        ctl,
        "--frames",
        "5",
        "--size",
        "160x120",
        "--probe-plane",
        "--gbuffer",
        str(npz),
        "--out",
        str(tmp_path / "follow.png"),
        timeout=180,
    )
    assert r.returncode == 0, r.stderr
    g = np.load(npz)
    assert (g["kind"] == KIND_PROBE).sum() > 0
    assert "nav_cube" in g.files and g["nav_cube"][3] > 0


def test_the_probe_plane_is_the_workspace_views_default_and_can_be_turned_off(daemon, tmp_path):
    """On by default in the workspace view; `--no-probe-plane` turns it off, and then the
    molecule layer holds however the probe moves."""
    from sasprobe.render.app import RenderOptions

    pub, ctl = daemon
    assert RenderOptions(connect=pub).effects().probe_plane  # the default of the workspace view
    assert not RenderOptions(connect=pub, probe_plane=False).effects().probe_plane
    report = tmp_path / "r.json"
    r = run_cli(
        "render",
        "--headless",
        "--connect",
        pub,
        "--control",
        ctl,
        "--frames",
        "6",
        "--size",
        "160x120",
        "--no-probe-plane",
        "--report",
        str(report),
        "--out",
        str(tmp_path / "plane.png"),  # PNGs: a video of a live daemon is paced
        timeout=180,
    )
    assert r.returncode == 0, r.stderr
    layer = json.loads(report.read_text())["molecule_layer"]
    assert layer["drawn"] + layer["kept"] == 6 and layer["kept"] >= 4, (
        layer
    )  # the probe moved: the layer held


def test_no_daemon_is_one_line():
    r = run_cli(
        "render",
        "--headless",
        "--connect",
        free_tcp_endpoint(),
        "--control",
        free_tcp_endpoint(),
        "--size",
        "160x120",
        timeout=120,
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "no daemon answered" in lines[0], r.stderr


def test_malformed_messages_are_dropped_and_counted(daemon, crambin):
    """A stand-in publisher (a real PUB socket) sends valid and broken messages."""
    with ControlClient(daemon[1]) as client:
        real_scene = client.get_scene()
    endpoint = free_tcp_endpoint()
    sock = zmq.Context.instance().socket(zmq.PUB)
    sock.linger = 0
    make_curve_server(
        sock, load_server_keys(ensure_local_keys())
    )  # as a daemon on loopback TCP does
    sock.bind(endpoint)
    link = DaemonSource(endpoint, free_tcp_endpoint())
    try:
        first = Pose(
            seq=1,
            proxy_A=np.array([1.0, 2.0, 3.0]),
            touched_atom=5,
            flags=FLAG_CONTACT,
            cube_center_A=np.array([1.0, 2.0, 3.0]),
            cube_half_A=6.0,
        )
        deadline = time.monotonic() + 20
        while link.subscriber.pose is None and time.monotonic() < deadline:  # until subscribed
            sock.send_multipart([b"pose", encode_pose(first)])
            time.sleep(0.05)
            link.poll()
        assert link.subscriber.pose is not None
        before = link.readout().dropped
        garbage = [
            [b"pose", b"too short"],
            [b"scene", b"{not json"],
            [b"scene", b'{"version": 1}'],
            [b"posed", b"x"],
            [b"pose"],
        ]  # (a topic outside pose/scene is filtered by ZeroMQ itself)
        for frames in garbage:
            sock.send_multipart(frames)
        good = Pose(
            seq=2,
            proxy_A=np.array([4.0, 5.0, 6.0]),
            touched_atom=7,
            flags=FLAG_CONTACT,
            cube_center_A=np.array([4.0, 5.0, 6.0]),
            cube_half_A=5.0,
        )
        sock.send_multipart([b"pose", encode_pose(good)])
        sock.send_multipart([b"scene", encode_scene(real_scene)])
        while link.subscriber.scene is None and time.monotonic() < deadline:
            link.poll()
            time.sleep(0.02)
        assert link.readout().dropped - before == len(garbage)
        scene = SceneState(crambin)
        link.apply(scene)
        np.testing.assert_array_equal(scene.probe.center, [4.0, 5.0, 6.0])
        assert scene.probe.touched_atom == 7
        np.testing.assert_array_equal(scene.nav_cube.center, [4.0, 5.0, 6.0])
        assert scene.nav_cube.half == 5.0
    finally:
        link.close()
        sock.close()


def test_the_grid_follows_the_daemons_probe_radius(gl):
    """A daemon feeling with a 2.0 Å probe: the renderer's grid (navigation-cube culling,
    and the lighting's GPU grid) is rebuilt with the daemon's radius, not its own default."""
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS
    from sasprobe.render.lighting.settings import LightingSettings

    radius = 2.0
    assert radius != DEFAULT_PROBE_RADIUS
    with DaemonProcess(
        "--probe-radius",
        str(radius),
        device=ORBIT,
        pub=free_tcp_endpoint(),
        ctl=free_tcp_endpoint(),
    ) as d:
        link = DaemonSource(d.pub, d.ctl)
        try:
            link.wait_ready(60.0)
            deadline = time.monotonic() + 20
            while link.subscriber.scene is None and time.monotonic() < deadline:
                link.poll()
                time.sleep(0.02)
            structure = link.take_new_structure()
            scene = SceneState(
                structure
            )  # the renderer's own default radius, until the daemon's arrives
            np.testing.assert_allclose(scene.grid.radii, structure.vdw_radii + DEFAULT_PROBE_RADIUS)
            link.apply(scene)
        finally:
            link.close()
    np.testing.assert_allclose(scene.grid.radii, structure.vdw_radii + radius)
    assert scene.probe.radius == radius
    renderer = Renderer(gl, scene, (64, 48))
    try:
        lighting = renderer.install_lighting(
            LightingSettings(shadows="hard", ao=replace(AOSettings(), mode="off"))
        )
        scene.effects.shadows = True
        renderer.render(Camera.fitted(*scene.bounding_sphere(), 64 / 48))
        assert lighting.grid.max_shell == pytest.approx(radius)
    finally:
        renderer.release()


def test_renderers_follow_the_daemons_colour_scheme(daemon, crambin):
    """`set color_scheme` reaches every renderer through the scene; a renderer's own choice
    stands while the daemon says null, and a bad name is refused."""
    from sasprobe.protocol.control import ProtocolError, validate_set_args

    pub, ctl = daemon
    link = DaemonSource(pub, ctl)
    scene = SceneState(crambin, effects=Effects(color_scheme="residue"))  # this renderer's --color
    try:
        with ControlClient(ctl) as client:

            def settled(expected) -> dict:
                deadline = time.monotonic() + 20
                while time.monotonic() < deadline:
                    link.poll()
                    state = link.subscriber.scene
                    if state is not None and state.get("color_scheme") == expected:
                        return state
                    time.sleep(0.02)
                raise AssertionError(f"the scene never said color_scheme={expected}")

            settled(None)
            link.apply(scene)
            assert scene.color_scheme() == "residue"  # null: the renderer keeps its own
            client.set(color_scheme="polymer")
            settled("polymer")
            link.apply(scene)
            assert scene.color_scheme() == "polymer"
            scene.effects.color_scheme = "sas"  # the window's C key still works ...
            link.apply(scene)
            assert scene.color_scheme() == "sas"  # ... until the daemon changes it again
            with pytest.raises(ProtocolError, match="color_scheme must be one of"):
                validate_set_args({"color_scheme": "rainbow"})
            client.set(color_scheme=None)
            settled(None)
            link.apply(scene)
            assert scene.color_scheme() == "sas"
    finally:
        link.close()


def test_a_headless_renderer_draws_the_structure_the_daemon_loads_next(tmp_path):
    """The daemon loads another structure mid-run: the headless renderer rebuilds for it (a
    picture of the old atoms in the new poses' frame would be wrong, and the probe light
    and the cube would lie far from its grid). Every sphere pixel of the last frame lies on
    an atom of the new structure, as the structure file places it."""
    from sasprobe.molecule import load_structure
    from sasprobe.render.gl.targets import KIND_SPHERE

    from tests.conftest import REPO_ROOT

    def wait_for(said: str, why: str) -> None:
        deadline = time.monotonic() + 120
        while said not in log.read_text():
            if time.monotonic() > deadline or proc.poll() is not None:
                raise AssertionError(f"{why}: not said in 120 s\n{log.read_text()[-2000:]}")
            time.sleep(0.2)

    path = REPO_ROOT / "tests" / "data" / "pdb" / "1oky.pdb.gz"
    npz, log = tmp_path / "g.npz", tmp_path / "render.log"
    with DaemonProcess("--seconds", "300", device=ORBIT) as d, open(log, "w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "sasprobe", "-v", "render", "--headless", "--connect", d.pub]
            + ["--control", d.ctl, "--seconds", "240", "--size", "160x120"]
            + ["--gbuffer", str(npz), "--out", str(tmp_path / "follow.mp4")],
            stdout=subprocess.DEVNULL,
            stderr=err,
            env=dict(os.environ, PYTHONUNBUFFERED="1", PYTHONFAULTHANDLER="1"),
        )
        try:
            wait_for("daemon structure: 1crn", "the first structure")
            with ControlClient(d.ctl) as client:
                client.load(path=path, timeout_s=120)
            wait_for("daemon structure: 1oky", "the structure loaded next")
            time.sleep(2.0)  # frames of it
            proc.send_signal(signal.SIGINT)  # ends after the current frame, the G-buffer written
            assert proc.wait(timeout=120) == 130, log.read_text()[-2000:]  # "interrupted"
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=30)
        d.stop(signal.SIGINT)
    g = np.load(npz)
    new = load_structure(path)
    ids, on = g["atom_id"], g["kind"] == KIND_SPHERE
    assert on.sum() > 50 and ids[on].max() < new.n_atoms, (on.sum(), ids[on].max())
    points, atoms = g["position"][on], ids[on]
    gap = np.linalg.norm(points - new.positions[atoms], axis=1) - new.vdw_radii[atoms]
    assert np.mean(np.abs(gap) < 0.02) > 0.99, np.percentile(np.abs(gap), [50, 99])


def test_a_long_frame_is_not_the_daemons_silence(monkeypatch):
    """A renderer short of CPU spends seconds on a frame, and the next poll may find nothing
    yet: the silence that ends a headless run is counted from that poll, not from the last
    message (a real PUB socket; the follower's clock stepped by hand)."""
    from sasprobe.protocol import follow as follow_module
    from sasprobe.protocol.follow import STALE_S, DaemonFollow

    clock = [1000.0]
    endpoint = free_tcp_endpoint()
    sock = zmq.Context.instance().socket(zmq.PUB)
    sock.linger = 0
    make_curve_server(sock, load_server_keys(ensure_local_keys()))
    sock.bind(endpoint)
    link = DaemonFollow(lambda served: served, endpoint, free_tcp_endpoint())
    try:
        deadline = time.monotonic() + 20
        while not link.poll() and time.monotonic() < deadline:  # until subscribed
            sock.send_multipart([b"pose", encode_pose(Pose(seq=1))])
            time.sleep(0.05)
        monkeypatch.setattr(follow_module.time, "monotonic", lambda: clock[0])
        sock.send_multipart([b"pose", encode_pose(Pose(seq=2))])
        for _ in range(500):  # (the clock is stepped by hand now)
            if link.poll():
                break
            time.sleep(0.01)
        assert link.lost_for_s() == 0.0
        clock[0] += 2 * STALE_S  # a frame that long, and nothing in the poll after it
        assert not link.poll()
        assert link.connected and link.lost_for_s() == 0.0
        clock[0] += 2 * STALE_S  # polling on, still nothing: the daemon is gone
        assert not link.poll()
        assert not link.connected and link.lost_for_s() == 2 * STALE_S
    finally:
        link.close()
        sock.close()
