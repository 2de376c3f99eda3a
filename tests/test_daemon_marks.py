"""Marks without a daemon process: their wire form (scene key, control commands),
the daemon's bookkeeping, the badges every renderer draws, and the CLI's one-line errors.

The badge check projects each mark with the frame's own view and projection in numpy and
finds the badge as the pixels that differ from the same frame drawn without marks.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from sasprobe.daemon.marks import Marks
from sasprobe.protocol.control import ProtocolError, decode_request, encode_request
from sasprobe.protocol.scene import MAX_MARK_LABEL, MAX_MARKS, SceneError, validate_marks

from sasprobe.common.errors import UserError
from tests.conftest import REPO_ROOT
from tests.support.daemon_process import cli_many


def _request(cmd, **args):
    return decode_request(encode_request(cmd, args))


def test_mark_and_findings_requests_are_checked():
    assert _request("mark").args == {}
    assert _request("mark", label="entrance").args == {"label": "entrance"}
    assert _request("findings", dir="out", probe_radius_A=1.6).args["probe_radius_A"] == 1.6
    for cmd, args, message in [
        ("mark", {"label": 3}, "string"),
        ("mark", {"label": "x" * (MAX_MARK_LABEL + 1)}, "at most"),
        ("mark", {"label": "two\nlines"}, "printable"),
        ("mark", {"where": 1}, "only 'label'"),
        ("findings", {}, "'dir'"),
        ("findings", {"dir": "out", "probe_radius_A": -1}, "> 0"),
        ("findings", {"dir": "out", "depth": 2}, "takes 'dir'"),
    ]:
        with pytest.raises(ProtocolError, match=message):
            _request(cmd, **args)


def test_scene_marks_are_validated():
    good = [{"id": 1, "label": "a", "position_A": [1.0, 2.0, 3.0], "seq": 10, "source": "control"}]
    assert validate_marks(good) == good
    for bad in (
        [{**good[0], "position_A": [1.0, 2.0]}],
        [{**good[0], "id": -1}],
        [{**good[0], "label": None}],
        "not a list",
        [dict(good[0]) for _ in range(MAX_MARKS + 1)],
    ):
        with pytest.raises(SceneError):
            validate_marks(bad)


def test_marks_are_numbered_belong_to_one_structure_and_are_bounded():
    marks = Marks()
    first = marks.drop(5, np.array([1.0, 2.0, 3.0]), None, "button", "sha-a")
    second = marks.drop(9, np.array([4.0, 5.0, 6.0]), "pocket", "control", "sha-a")
    assert (first["id"], first["label"], second["id"], second["label"]) == (
        1,
        "mark 1",
        2,
        "pocket",
    )
    assert [m["position_A"] for m in marks.scene("sha-a")] == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    json.dumps(marks.scene("sha-a"), allow_nan=False)  # what goes into the scene is plain JSON
    assert marks.scene("sha-b") == []  # another structure: the old marks mean nothing there
    assert marks.drop(1, np.zeros(3), None, "control", "sha-b")["id"] == 1
    for k in range(MAX_MARKS - 1):
        marks.drop(k, np.zeros(3), None, "control", "sha-b")
    with pytest.raises(UserError, match=f"at most {MAX_MARKS}"):
        marks.drop(0, np.zeros(3), None, "control", "sha-b")
    marks.restore({"id": MAX_MARKS + 1, "label": "from a file", "position_A": [0, 0, 0]})
    assert len(marks.scene("sha-b")) == MAX_MARKS  # a replayed file holds no more


def test_the_mark_button_marks_the_newest_proxy_except_in_a_replay():
    from types import SimpleNamespace

    from sasprobe.daemon.marks import drop_mark, mark_button

    recorded, scenes = [], []

    def daemon(replay: bool, proxy):
        return SimpleNamespace(
            pipeline=SimpleNamespace(
                last_output=None if proxy is None else SimpleNamespace(proxy_A=np.array(proxy))
            ),
            marks=Marks(),
            structure=SimpleNamespace(sha256="s"),
            device=SimpleNamespace(recorded_session=lambda: object() if replay else None),
            record_control=lambda seq, cmd, args: recorded.append((seq, cmd, args)),
            rebuild_scene=lambda: scenes.append(1),
        )

    live = daemon(False, [1.0, 2.0, 3.0])
    mark_button(live, 42)
    assert recorded == [
        (
            42,
            "mark",
            {
                "id": 1,
                "label": "mark 1",
                "position_A": [1.0, 2.0, 3.0],
                "seq": 42,
                "source": "button",
            },
        )
    ] and scenes == [1]
    assert live.marks.scene("s")[0]["position_A"] == [1.0, 2.0, 3.0]
    replay = daemon(True, [1.0, 2.0, 3.0])
    mark_button(replay, 43)  # the recorded `mark` records bring a replay's marks
    assert replay.marks.scene("s") == [] and len(recorded) == 1
    mark_button(daemon(False, None), 44)  # no valid reading yet: logged, nothing marked
    assert len(recorded) == 1
    with pytest.raises(UserError, match="no probe position"):
        drop_mark(daemon(False, None), 45, "x", "control")


def _frame(gl, crambin, marks, enabled=True):
    from sasprobe.render.camera import Camera
    from sasprobe.render.renderer import Renderer
    from sasprobe.render.scene_state import Effects, Mark, SceneState

    scene = SceneState(crambin, effects=Effects(fxaa=False, marks=enabled))
    scene.marks = [Mark(k + 1, f"m{k + 1}", tuple(map(float, p))) for k, p in enumerate(marks)]
    renderer = Renderer(gl, scene, (320, 240))
    center, radius = scene.bounding_sphere()
    camera = Camera.fitted(center, radius, 320 / 240, direction=(0.0, 0.0, 1.0), up=(0.0, 1.0, 0.0))
    frame = renderer.render(camera)
    image = renderer.read_image(frame)
    view, proj = frame.view.copy(), frame.proj.copy()
    eye = camera.eye.copy()
    renderer.release()
    return image, view, proj, eye


def test_every_mark_is_a_numbered_badge_where_it_projects(gl, crambin):
    from sasprobe.render.passes.marks import BADGE_PX

    top = int(
        np.argmax(crambin.positions[:, 2])
    )  # nearest the camera looking down -z: nothing in front
    outside = crambin.positions[top] + [0.0, 0.0, crambin.vdw_radii[top] + 1.4]
    buried = crambin.positions.mean(axis=0)  # inside the molecule: drawn faded
    marks = [outside, buried]
    with_marks, view, proj, eye = _frame(gl, crambin, marks)
    without, *_ = _frame(gl, crambin, marks, enabled=False)
    changed = np.abs(with_marks.astype(int) - without.astype(int)).max(axis=2) > 8
    h, w = changed.shape
    strength = []
    for point in marks:
        clip = proj @ view @ np.array([*point, 1.0])
        x, y = (clip[0] / clip[3] * 0.5 + 0.5) * w, (0.5 - clip[1] / clip[3] * 0.5) * h
        box = changed[int(y) - BADGE_PX : int(y) + BADGE_PX, int(x) - BADGE_PX : int(x) + BADGE_PX]
        ys, xs = np.nonzero(box)
        assert xs.size > 100, "no badge at the mark"
        assert (
            abs(xs.mean() + int(x) - BADGE_PX - x) < 2.5
            and abs(ys.mean() + int(y) - BADGE_PX - y) < 2.5
        )
        strength.append(
            np.abs(with_marks.astype(int) - without.astype(int))[
                int(y), int(x) - 6 : int(x) + 6
            ].mean()
        )
    assert changed.sum() < 2 * BADGE_PX * BADGE_PX + 10, "nothing but the two badges changes"
    assert strength[1] < 0.7 * strength[0], "a mark behind atoms is drawn faded"


def test_user_errors_are_one_line():
    results = cli_many(
        ("replay", "missing.mcap", "--findings", "out-never-made"),
        ("replay", str(REPO_ROOT / "README.md"), "--probe-radius", "2"),
        ("replay", str(REPO_ROOT / "README.md"), "--findings", "out-never-made"),
    )
    for r in results:
        assert r.returncode == 2, r.stdout + r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    assert (
        "missing.mcap: no such file" in results[0].stderr
        and "not an MCAP file" in results[2].stderr
    )
    assert "--probe-radius goes with --findings" in results[1].stderr
    assert not (REPO_ROOT / "out-never-made").exists()
