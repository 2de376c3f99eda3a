"""Findings of a real session: one recording daemon (simulated arm diving into 1CRN) gets a
mark from a window's Enter key (under Xvfb) and one from `sasprobe mark` (the control
command), analyses itself through `sasprobe findings` (the control command `findings`),
and is killed with SIGKILL; the cut file gives findings up to
its last record, and replaying it through a second daemon gives the same marks. The
exports read back with gemmi and load in PyMOL where it is installed.

Oracles: the clearance against a brute-force minimum over every atom; the exported
files against gemmi's own reading; the marks against what the daemon answered.
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
from sasprobe.protocol.client import ControlClient

from tests.conftest import REPO_ROOT, run_cli, skip_or_fail
from tests.support.daemon_process import DaemonProcess
from tests.support.recordings import read_session, read_whole_track

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@pytest.fixture(scope="module")
def session(tmp_path_factory, request):
    """The cut recording, the marks the daemon answered with, and the daemon's own findings job."""
    folder = tmp_path_factory.mktemp("session")
    recording = folder / "session.mcap"
    display = _display(request)
    marks = []
    # The arm dives into a groove and rocks there: a short path, so the analysis takes seconds
    # however long the window part keeps the session going on a busy machine.
    with DaemonProcess("--record", str(recording), device="sim:dive") as d:
        with ControlClient(d.ctl) as client:
            time.sleep(1.0)
            if display is not None:  # a window following the daemon: its Enter key drops mark 1
                env = dict(
                    os.environ, SASPROBE_TEST_PUB=d.pub, SASPROBE_TEST_CTL=d.ctl, DISPLAY=display
                )
                r = subprocess.run(
                    [sys.executable, "-m", "tests.window_scripts.marks"],
                    capture_output=True,
                    text=True,
                    timeout=300,
                    env=env,
                    cwd=REPO_ROOT,
                )
                assert r.returncode == 0 and r.stdout.strip().endswith("keys ok"), (
                    r.stdout + r.stderr
                )
                marks.append(client.get_scene()["marks"][0])
            time.sleep(0.7)
            r = run_cli(
                "mark",
                "groove between two side chains",
                "--ctl",
                d.ctl,
                "--json",  # the control command
                timeout=300,
            )
            assert r.returncode == 0, r.stderr
            marks.append(json.loads(r.stdout)["mark"])
            r = run_cli(
                "findings",
                str(folder / "live"),
                "--ctl",
                d.ctl,
                "--json",  # waits for the daemon's job
                timeout=300,
            )
            assert r.returncode == 0, r.stderr
            job = json.loads(r.stdout)
            assert job == client.status()["findings"]
            time.sleep(0.5)
        d.stop(signal.SIGKILL)
    return {
        "folder": folder,
        "recording": recording,
        "marks": marks,
        "job": job,
        "window": display is not None,
    }


def _display(request) -> str | None:
    """The X server of the window part, or None where the window tests would skip."""
    try:
        return request.getfixturevalue("xvfb")
    except pytest.skip.Exception:
        return None


@pytest.fixture(scope="module")
def findings(session):
    """`sasprobe replay CUT --findings DIR` through the real CLI."""
    out = session["folder"] / "cut"
    r = run_cli("replay", str(session["recording"]), "--findings", str(out), "--json", timeout=300)
    assert r.returncode == 0, r.stderr
    assert "findings: passage" in r.stderr  # the long step shows progress
    return out, json.loads((out / "findings.json").read_text()), json.loads(r.stdout)


def _brute_clearance(structure, points):
    d = (
        np.linalg.norm(points[:, None, :] - structure.positions[None, :, :], axis=2)
        - structure.vdw_radii[None, :]
    )
    return d.min(axis=1)


def test_the_window_key_and_the_control_command_drop_numbered_marks(session):
    if not session["window"]:
        skip_or_fail(
            "no X server for the window's Enter key: Xvfb is not installed (Debian package xvfb)"
        )
    marks = session["marks"]
    assert [m["id"] for m in marks] == [1, 2]
    assert marks[0]["label"] == "mark 1" and marks[1]["label"] == "groove between two side chains"
    assert marks[0]["seq"] < marks[1]["seq"]


def test_a_killed_session_still_gives_findings_up_to_its_last_record(session, findings):
    from sasprobe.protocol.recording import scan

    assert not scan(session["recording"]).finished
    out, found, printed = findings
    last_pose = int(read_session(session["recording"]).seq.max())
    assert found["session"]["finished"] is False
    assert (
        found["path"]["points"][-1]["seq"] == last_pose
    )  # the path runs to the last recorded tick
    assert any("cut" in note for note in found["notes"])
    assert printed["findings"]["files"]["chart"] == "chart.png"
    for name in (
        "findings.json",
        "touched_residues.tsv",
        "marks.tsv",
        "chart.png",
        "path.pdb",
        "path.cif",
        "session.pml",
        "session.cxc",
        "structure.pdb",
    ):
        assert (out / name).stat().st_size > 0, name
    assert found["touched_residues"], "the dive presses into the surface: residues are touched"
    rows = (out / "touched_residues.tsv").read_text().splitlines()
    assert len(rows) == len(found["touched_residues"]) + 1
    for r in found["touched_residues"]:
        assert (
            0 < r["contact_s"] <= found["session"]["contact_s"] + 1e-9
            and r["first_s"] <= r["last_s"]
        )


def test_marks_survive_record_replay_and_findings(session, findings, tmp_path):
    """The findings of the cut file carry the marks as the daemon made them; a daemon replaying
    that file records them again at the same ticks."""
    out, found, _ = findings
    want = [(m["id"], m["label"], m["seq"]) for m in session["marks"]]
    assert [(m["id"], m["label"], m["seq"]) for m in found["marks"]] == want
    for got, mark in zip(found["marks"], session["marks"]):
        assert got["position_A"] == mark["position_A"]
        nearest = got["residues_within_4A"]
        assert nearest == sorted(nearest, key=lambda r: r["distance_A"]) and all(
            r["distance_A"] <= 4 for r in nearest
        )
    # The cut recording replayed through a daemon is recorded again with the same marks.
    again = tmp_path / "again.mcap"
    with DaemonProcess(
        "--device", f"replay:{session['recording']}", "--speed", "max", "--record", str(again)
    ) as d:
        assert d.proc.wait(timeout=120) == 0, d.stderr

    def key(m):
        return m["id"], m["label"], m["seq"], m["position_A"], round(m["t_s"], 9)

    # what the findings read their marks with
    assert [key(m) for m in read_whole_track(again).marks] == [key(m) for m in found["marks"]]


def test_the_daemon_analyses_its_own_recording(session):
    job = session["job"]
    assert job["state"] == "done", job
    live = json.loads((Path(job["dir"]) / "findings.json").read_text())
    assert live["session"]["finished"] is False  # read while the daemon was still writing it
    assert [m["id"] for m in live["marks"]] == [m["id"] for m in session["marks"]]
    assert (Path(job["dir"]) / "chart.png").stat().st_size > 0


def test_the_analysis_finishes_when_the_daemon_has_gone(session, tmp_path):
    """The daemon's analysis child, its result pipe closed (the daemon stopped meanwhile),
    still writes its files and ends with one line, no traceback."""
    out = tmp_path / "late"
    child = subprocess.Popen(
        [sys.executable, "-m", "sasprobe.daemon.findings", str(session["recording"]), str(out)]
        + ["--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO_ROOT,
    )
    child.stdout.close()  # what the daemon's end does to the pipe
    try:
        _, err = child.communicate(timeout=300)
    finally:
        child.kill()
    assert child.returncode == 0 and "Traceback" not in err, err
    assert (
        err.strip().splitlines()[-1]
        == f"findings: written into {out} (the daemon that asked has gone)"
    )
    assert json.loads((out / "findings.json").read_text())["session"]["finished"] is False


def test_clearance_equals_a_brute_force_minimum_on_recorded_points(session):
    from sasprobe.molecule.clearance import ClearanceField

    track = read_whole_track(session["recording"])
    rng = np.random.default_rng(18)
    picked = track.proxy_A[rng.choice(track.n_ticks, 300, replace=False)]
    points = np.concatenate(
        [picked, picked + rng.normal(scale=2.0, size=picked.shape), picked[:20] * 4.0]
    )  # on the path, around it (inside atoms too), far outside the grid
    got, atom = ClearanceField.of(track.structure).clearance(points)
    want = _brute_clearance(track.structure, points)
    assert np.max(np.abs(got - want)) <= 1e-9
    s = track.structure
    assert np.allclose(
        np.linalg.norm(points - s.positions[atom], axis=1) - s.vdw_radii[atom], want, atol=1e-9
    )
    # The recorded proxy touching the SAS is exactly one probe radius from the vdW surface.
    touching = track.proxy_A[track.contact][::50]
    assert np.max(np.abs(_brute_clearance(s, touching) - track.probe_radius_A)) < 1e-6


def test_the_exports_read_back_with_gemmi(findings):
    import gemmi

    out, found, _ = findings
    points = found["path"]["points"]
    for name, decimals in (("path.pdb", 2), ("path.cif", 4)):
        st = gemmi.read_structure(str(out / name))
        chains = {ch.name: ch for ch in st[0]}
        path = [res[0] for res in chains["P"]]
        assert len(path) == len(points)
        for atom, point in zip(path, points):
            assert atom.b_iso == pytest.approx(point["passage_A"], abs=0.6 * 10**-decimals)
            assert np.allclose(atom.pos.tolist(), point["position_A"], atol=1e-3)
        marks = [(res.seqid.num, res[0].pos.tolist()) for res in chains["M"]]
        assert [m[0] for m in marks] == [m["id"] for m in found["marks"]]
        for (_, pos), mark in zip(marks, found["marks"]):
            assert np.allclose(pos, mark["position_A"], atol=1e-3)
    protein = gemmi.read_structure(str(out / "structure.pdb"))
    assert protein[0].count_atom_sites() == found["structure"]["n_atoms"]


def test_the_scripts_load_in_pymol(findings):
    try:
        import pymol  # noqa: F401
    except ImportError:
        skip_or_fail("PyMOL is not installed (pip install -e '.[peers]')")
    out, found, _ = findings
    check = (
        "import sys, pymol; from pymol import cmd; pymol.finish_launching(['pymol', '-cq']);"
        "cmd.load(sys.argv[1]);"
        "print('NAMES', ' '.join(cmd.get_names('all') + cmd.get_names('selections')));"
        "print('COUNTS', cmd.count_atoms('path and chain P'), cmd.count_atoms('path and chain M'),"
        " cmd.count_atoms('touched'), cmd.count_atoms('structure'))"
    )
    r = subprocess.run(
        [sys.executable, "-c", check, str(out / "session.pml")],
        capture_output=True,
        text=True,
        timeout=120,
        cwd="/",
    )
    assert r.returncode == 0, r.stderr
    assert "Error" not in r.stdout, r.stdout
    names = next(line for line in r.stdout.splitlines() if line.startswith("NAMES")).split()[1:]
    assert {"structure", "path", "touched"} <= set(names), names
    counts = [
        int(v)
        for v in next(line for line in r.stdout.splitlines() if line.startswith("COUNTS")).split()[
            1:
        ]
    ]
    touched = {(t["chain"], t["number"]) for t in found["touched_residues"]}
    import gemmi

    protein = gemmi.read_structure(str(out / "structure.pdb"))
    want_touched = sum(
        len(res) for ch in protein[0] for res in ch if (ch.name, res.seqid.num) in touched
    )
    assert counts == [
        len(found["path"]["points"]),
        len(found["marks"]),
        want_touched,
        found["structure"]["n_atoms"],
    ]
