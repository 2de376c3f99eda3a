"""Recordings read as streams: a file of the first format (tests/data/recordings/) read as
that format says, verified and analysed as it was when it was written; results that do
not depend on where the blocks of ticks end; the explored path against the rule written
out tick by tick, and its bound on long sessions."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from sasprobe.protocol.pose import FLAG_FAULT

from tests.conftest import REPO_ROOT, run_cli
from tests.support.recordings import read_session

FIRST_FORMAT = REPO_ROOT / "tests" / "data" / "recordings" / "scan-v1.mcap"
FIRST_FINDINGS = FIRST_FORMAT.with_suffix(".findings.json")


def _json_ticks(path: Path) -> tuple[list[tuple[dict, dict]], list[dict]]:
    """The first format's ticks as its README section describes them, read with the mcap
    library and json: each `device` message with the `pose` message after it; and the
    control records."""
    from mcap.stream_reader import StreamReader

    ticks, control, device = [], [], None
    topics = {}
    with open(path, "rb") as f:
        for record in StreamReader(f).records:
            name = type(record).__name__
            if name == "Channel":
                topics[record.id] = record.topic
            elif name == "Message":
                topic = topics[record.channel_id]
                if topic == "device":
                    device = json.loads(record.data)
                elif topic == "pose":
                    pose = json.loads(record.data)
                    assert device["seq"] == pose["seq"]
                    ticks.append((device, pose))
                elif topic == "control":
                    control.append(json.loads(record.data))
    return ticks, control


def _floats(values) -> list[float]:
    return [math.nan if v is None else v for v in values]


def test_a_first_format_file_reads_as_that_format_says():
    ticks, control = _json_ticks(FIRST_FORMAT)
    s = read_session(FIRST_FORMAT)
    assert (
        s.n_ticks == len(ticks) and control[0]["cmd"] == "start" and s.start == control[0]["args"]
    )
    assert s.events == control[1:] and {"mark", "set"} <= {e["cmd"] for e in s.events}
    assert s.errors and np.isnan(s.position_mm).any()  # a failed read and a non-finite one
    for i, (device, pose) in enumerate(ticks):
        state, error = s.state(i)
        assert error == device["error"] and int(s.seq[i]) == device["seq"]
        assert (state is None) == (device["t_ns"] is None)
        if state is not None:
            assert state.t_ns == device["t_ns"] and state.buttons == device["buttons"]
            np.testing.assert_array_equal(state.position_mm, _floats(device["position_mm"]))
            np.testing.assert_array_equal(state.velocity_mm_s, _floats(device["velocity_mm_s"]))
        assert s.late_periods[i] == device["late_periods"]
        assert s.force_n[i].tolist() == pose["force_N"] and s.flags[i] == pose["flags"]
        assert s.ticks.pose["proxy_A"][i].tolist() == pose["proxy_A"]


@pytest.fixture(scope="module")
def first_format_replay():
    out = run_cli("replay", str(FIRST_FORMAT), "--verify", "--json")
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_a_first_format_file_verifies_to_zero(first_format_replay):
    ticks, control = _json_ticks(FIRST_FORMAT)
    summary, verify = first_format_replay["summary"], first_format_replay["verify"]
    assert summary["format"] == 1 and summary["ticks"] == len(ticks) and summary["seq_gaps"] == 0
    assert verify["ok"] and verify["max_force_diff_n"] == 0.0 and verify["ticks"] == len(ticks)
    assert verify["events_applied"] == len(control) - 1  # after `start`, each before a tick
    assert verify["fault_ticks"] == sum(1 for _, p in ticks if p["flags"] & FLAG_FAULT)


def _without_paths(found: dict) -> dict:
    return {k: v for k, v in found.items() if k not in ("files", "recording")}


def _close(a, b, path="") -> None:
    """Equal, floats to round-off (a sum taken a block at a time)."""
    if isinstance(a, dict):
        assert set(a) == set(b), path
        for k in a:
            _close(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for k, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{path}[{k}]")
    elif isinstance(a, float):
        assert b == pytest.approx(a, rel=1e-12, abs=1e-12), path
    else:
        assert a == b, path


def _analysed(path: Path) -> dict:
    from sasprobe.daemon.findings import analyse
    from sasprobe.daemon.findings.session import read_track

    return analyse(read_track(path)).found


def test_a_first_format_file_gives_the_findings_it_gave_when_written(monkeypatch):
    """The same findings, to round-off, whether the ticks come in whole blocks or in blocks
    of 7 (a mark, the bottleneck's neighbours, failed reads across their ends)."""
    from sasprobe.protocol import recording

    then = _without_paths(json.loads(FIRST_FINDINGS.read_text()))
    assert then["bottleneck"] is not None and then["marks"]
    _close(then, _without_paths(_analysed(FIRST_FORMAT)))
    monkeypatch.setattr(recording, "BLOCK_TICKS", 7)
    _close(then, _without_paths(_analysed(FIRST_FORMAT)))


# ---------------------------------------------------------------- the explored path


def _rule(points, touched, marked, spacing, pin):
    """The path's rule tick by tick, as daemon/findings/path.py's docstring states it."""
    kept = [0]
    for i in range(1, len(points)):
        moved = math.dist(points[i], points[kept[-1]])
        wedged = len(touched[i]) >= 3 and touched[i] != touched[i - 1]
        if (
            i in marked
            or i == len(points) - 1
            or moved >= spacing
            or (wedged and (touched[i] != touched[kept[-1]] or moved >= pin))
        ):
            kept.append(i)
    return kept


def _wander(n: int, seed: int, step: float):
    rng = np.random.default_rng(seed)
    points = np.cumsum(rng.normal(scale=step, size=(n, 3)), axis=0)
    atoms = [
        frozenset(rng.choice(6, size=rng.integers(0, 5), replace=False).tolist()) for _ in range(n)
    ]
    contact = rng.random(n) < 0.6
    force = rng.random(n) * contact
    return points, atoms, contact, force


def _build(points, atoms, contact, force, marked, block):
    from sasprobe.daemon.findings.path import PathBuilder

    builder = PathBuilder()
    for start in range(0, len(points), block):
        stop = min(start + block, len(points))
        builder.add_block(
            start,
            list(range(start, stop)),
            points[start:stop].tolist(),
            [0.0] * (stop - start),
            contact[start:stop].tolist(),
            force[start:stop].tolist(),
            atoms[start:stop],
            {m - start for m in marked if start <= m < stop},
        )
    return builder.finish()


@pytest.mark.parametrize("block", [1, 13, 5000])
def test_the_path_keeps_the_ticks_the_rule_keeps_with_their_contact_and_force(block):
    from sasprobe.daemon.findings.path import PIN_SPACING_A, SPACING_A

    points, atoms, contact, force = _wander(5000, 3, 0.05)
    marked = {700, 701, 2500}
    path = _build(points, atoms, contact, force, marked, block)
    kept = _rule(points, atoms, marked, SPACING_A, PIN_SPACING_A)
    assert path.ticks.tolist() == kept and path.spacing_A == SPACING_A
    starts = [0, *[k + 1 for k in kept[:-1]]]
    for k, (a, b) in enumerate(zip(starts, kept)):
        assert path.contact[k] == contact[a : b + 1].any()
        assert path.force_max_N[k] == force[a : b + 1].max()
        assert path.contact_ticks[k] == contact[a : b + 1].sum()


def test_a_long_path_stays_within_its_bound_and_loses_no_contact_or_force():
    from sasprobe.daemon.findings.path import MAX_POINTS, SPACING_A

    points, atoms, contact, force = _wander(60_000, 4, 0.3)  # ~ 30,000 Å of wandering
    marked = {10_000, 40_000}
    path = _build(points, atoms, contact, force, marked, 4096)
    assert path.n_points <= MAX_POINTS and path.spacing_A > SPACING_A
    assert path.ticks[0] == 0 and path.ticks[-1] == 59_999 and marked <= set(path.ticks.tolist())
    assert path.contact_ticks.sum() == contact.sum()  # each tick is in exactly one point's span
    assert path.force_max_N.max() == force.max()
    gaps = np.linalg.norm(np.diff(path.position_A, axis=0), axis=1)
    wedges = np.array([len(atoms[t]) >= 3 for t in path.ticks[1:]])
    kept_for_distance = ~wedges & ~np.isin(path.ticks[1:], [*marked, 59_999])
    assert np.all(gaps[kept_for_distance] >= path.spacing_A - 1e-9)


def test_verify_finds_a_force_that_was_not_the_pipelines(tmp_path):
    """The first-format file written again with one tick's recorded force changed: `--verify`
    names that tick and the difference, and only it."""
    from mcap.records import Attachment, Channel, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import Writer
    from sasprobe.daemon.recording.verify import verify_recording

    ticks, _ = _json_ticks(FIRST_FORMAT)
    target = ticks[len(ticks) // 2][1]["seq"]
    changed = tmp_path / "changed.mcap"
    topics = {}
    with open(FIRST_FORMAT, "rb") as src, open(changed, "wb") as dst:
        writer = Writer(dst)
        writer.start(profile="sasprobe")
        for record in StreamReader(src).records:
            if isinstance(record, Schema):
                writer.register_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel):
                topics[record.id] = record.topic
                writer.register_channel(record.topic, record.message_encoding, record.schema_id)
            elif isinstance(record, Message):
                data = record.data
                if topics[record.channel_id] == "pose" and json.loads(data)["seq"] == target:
                    pose = json.loads(data)
                    pose["force_N"][1] += 0.125
                    data = json.dumps(pose).encode()
                writer.add_message(record.channel_id, record.log_time, data, record.publish_time)
            elif isinstance(record, Attachment):
                writer.add_attachment(
                    0, record.log_time, record.name, record.media_type, record.data
                )
            elif isinstance(record, Metadata):
                writer.add_metadata(record.name, record.metadata)
        writer.finish()
    report = verify_recording(changed)
    assert not report.ok and report.ticks == len(ticks)
    assert report.ticks_with_force_diff == 1 and report.first_diff_seq == target
    assert report.max_force_diff_n == 0.125 and report.flag_mismatches == 0
