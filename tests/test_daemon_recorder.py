"""Recording to MCAP and reading it back: exact values (through sasprobe's reader and through
the README's tables), cut files, recovery, bounded memory."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from sasprobe.daemon.recording.writer import Recorder
from sasprobe.devices.base import PHANTOM_OMNI_LIMITS, DeviceInfo, DeviceState
from sasprobe.protocol.pose import (
    FLAG_CLAMPED,
    FLAG_CLUTCHED,
    FLAG_CONTACT,
    FLAG_DRIFTING,
    FLAG_FAULT,
    FLAG_RAMPING,
    Pose,
)
from sasprobe.protocol.recording import Recording, RecordingError, recover, scan, summarize
from sasprobe.protocol.ticks import TickBlock

from tests.support.bounded import join
from tests.support.recordings import read_session, reference_ticks

# Flag sets a daemon writes (tests/support/schema_check.py checks each pose's flags against
# its fields).
_FLAGS = (
    0,
    FLAG_CONTACT,
    FLAG_CONTACT | FLAG_CLAMPED,
    FLAG_DRIFTING,
    FLAG_RAMPING,
    FLAG_CONTACT | FLAG_RAMPING,
    FLAG_CLUTCHED,
)
_SETTINGS = {
    "probe_radius_A": 1.4,
    "method": "proxy",
    "stiffness_n_per_mm": 0.3,
    "damping_n_s_per_m": 0.0,
    "cube_half_A": None,
}


def _write(path, n=600, flush_interval_s=0.02):
    """A recording of n ticks with a non-finite reading (tick 100) and a failed read (tick 200),
    every record as the protocol documents it."""
    rng = np.random.default_rng(1)
    rec = Recorder(
        path,
        {"daemon_version": "test", "device": "sim", "rate_hz": "1000.0", "started_unix_s": "0"},
        flush_interval_s=flush_interval_s,
    )
    rec.offer_structure(1, "tiny", b"ATOM tiny structure bytes\n")
    rec.offer_json(
        "control",
        2,
        {
            "seq": 0,
            "cmd": "start",
            "args": {
                "settings": _SETTINGS,
                "structure_sha256": _sha(b"ATOM tiny structure bytes\n"),
                "structure_name": "tiny",
                "keep_water": False,
                "rate_hz": 1000.0,
                "device": DeviceInfo("x", "y", PHANTOM_OMNI_LIMITS).as_dict(),
            },
        },
    )
    truth = []
    for seq in range(n):
        st = DeviceState(
            t_ns=seq * 1_000_000,
            position_mm=rng.normal(size=3) * 10,
            velocity_mm_s=rng.normal(size=3),
            buttons=seq % 3,
        )
        error = None
        if seq == 100:
            st.position_mm[1] = math.nan
        if seq == 200:
            st, error = None, "read timed out"
        flags = FLAG_FAULT if seq in (100, 200) else _FLAGS[seq % len(_FLAGS)]
        force = np.zeros(3) if flags & (FLAG_FAULT | FLAG_CLUTCHED) else rng.normal(size=3)
        pose = Pose(
            seq=seq,
            force_N=force,
            flags=flags,
            proxy_A=rng.normal(size=3),
            touched_atom=seq % 7 if flags & FLAG_CONTACT else -1,
        )
        rec.offer_tick(10 + seq, seq, st, error, 0.25, 1234, pose)
        truth.append((st, error, pose))
        if seq % 100 == 0:
            time.sleep(0.03)  # let flushes happen between ticks
    return rec, truth


def _sha(data: bytes) -> str:
    import hashlib

    return hashlib.sha256(data).hexdigest()


def test_round_trip_is_exact(tmp_path):
    path = tmp_path / "s.mcap"
    rec, truth = _write(path)
    stats = rec.close()
    assert scan(path).finished
    reference = reference_ticks(path)  # the mcap library and the README's tables
    batches = summarize(path).counts["ticks"]
    assert stats.dropped == 0 and stats.messages == batches + 1 and batches < len(truth) / 4
    session = read_session(path)
    assert session.n_ticks == len(reference) == len(truth) and session.missing_ticks == 0
    for i, (st, error, pose) in enumerate(truth):
        got, got_error = session.state(i)
        ref = reference[i]
        assert got_error == ref["error"] == error
        assert session.force_n[i].tolist() == list(ref["pose"]["force"]) == pose.force_N.tolist()
        assert session.flags[i] == ref["pose"]["flags"] == pose.flags
        assert ref["pose"]["seq"] == i and ref["late_periods"] == 0.25 and ref["read_ns"] == 1234
        if st is None:
            assert got is None and not ref["device_flags"] & 1
            continue
        assert got.t_ns == ref["t_ns"] == st.t_ns and got.buttons == ref["buttons"] == st.buttons
        np.testing.assert_array_equal(got.position_mm, st.position_mm)  # NaN stays NaN
        np.testing.assert_array_equal(ref["position_mm"], st.position_mm)
        np.testing.assert_array_equal(got.velocity_mm_s, st.velocity_mm_s)
    assert session.structure_bytes == b"ATOM tiny structure bytes\n"


def test_records_keep_their_place_between_ticks_and_structures_are_attached_once(tmp_path):
    """A control record offered between two ticks is read back between them (the batch of
    ticks is split there); the same structure offered again is not attached again."""
    path = tmp_path / "o.mcap"
    rec, _ = _write(path, n=50)
    rec.offer_structure(3, "tiny", b"ATOM tiny structure bytes\n")
    for seq in range(50, 60):
        if seq == 55:
            rec.offer_json("control", 5, {"seq": 55, "cmd": "recentre", "args": {}})
        rec.offer_tick(10 + seq, seq, None, "gone", 0.0, 0, Pose(seq=seq, flags=FLAG_FAULT))
    rec.close()
    order = []
    for item in Recording(path).stream():
        if isinstance(item, TickBlock):
            order.append(("ticks", int(item.seq[0]), int(item.seq[-1])))
        elif item.topic in ("control", "attachment"):
            order.append((item.topic, item.data.get("cmd")))
    assert order[:2] == [("attachment", None), ("control", "start")]
    assert order[2:] == [("ticks", 0, 54), ("control", "recentre"), ("ticks", 55, 59)]


def test_memory_does_not_grow_with_the_chunks(tmp_path):
    """One chunk per flush: the writer's index of them waits in a file, and the summary the
    file ends with still indexes every chunk (the mcap library reads through it)."""
    import tracemalloc

    from mcap.reader import make_reader

    path = tmp_path / "m.mcap"
    rec = Recorder(path, flush_interval_s=1e9)  # flushed by hand below
    rec._stop.set()
    rec._thread.join()
    tracemalloc.start()
    try:
        for burst in range(2):
            before = tracemalloc.get_traced_memory()[0]
            for seq in range(burst * 2000, (burst + 1) * 2000):
                rec._write(("tick", seq, seq, None, "x", 0.0, 0, Pose(seq=seq)))
                rec._write_ticks()
                rec._writer.flush()
            grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert grown < 2000 * 16, f"{grown} bytes kept for 2000 chunks"  # a chunk index: ~400 bytes
    rec.close()
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert len(reader.get_summary().chunk_indexes) == 4000
        assert sum(1 for _ in reader.iter_messages(topics=["ticks"])) == 4000


def test_cut_files_read_up_to_their_last_complete_record(tmp_path):
    path = tmp_path / "s.mcap"
    rec, truth = _write(path, flush_interval_s=0.005)
    rec.close()
    data = path.read_bytes()
    previous = -1
    for cut in np.linspace(200, len(data) - 1, 25).astype(int):
        part = tmp_path / f"cut{cut}.mcap"
        part.write_bytes(data[:cut])
        info = scan(part)
        assert not info.finished and info.end <= cut
        blocks = [b for b in Recording(part).stream() if isinstance(b, TickBlock)]
        seqs = TickBlock.join(blocks).seq.tolist() if blocks else []
        assert seqs == list(range(len(seqs)))  # a gap-free prefix of the session
        assert len(seqs) >= previous
        previous = len(seqs)
        out = tmp_path / f"fixed{cut}.mcap"
        summary = recover(part, out)
        assert scan(out).finished and summary.ticks == len(seqs)
    assert previous > len(truth) * 0.8


def test_not_a_recording(tmp_path):
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"hello")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        summarize(bad)


def test_recorder_refuses_to_overwrite(tmp_path):
    path = tmp_path / "exists.mcap"
    path.write_bytes(b"")
    from sasprobe.common.errors import UserError

    with pytest.raises(UserError, match="already exists"):
        Recorder(path)


def test_a_full_queue_drops_and_counts(tmp_path):
    rec = Recorder(tmp_path / "q.mcap", queue_limit=10, flush_interval_s=10)
    rec._stop.set()  # writer thread exits: nothing drains the queue
    join(rec._thread)
    for seq in range(25):
        rec.offer_tick(seq, seq, None, "x", 0.0, 0, Pose(seq=seq))
    assert rec.dropped == 15
    assert rec.close().dropped == 15
