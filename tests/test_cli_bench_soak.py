"""`sasprobe bench soak`'s session, short and unpaced: rounds of subscribers joining and
leaving, control calls and loads of two structures in turn beside two headless renderers
and injected device faults. Counted, not timed: after the first round (the structure
worker started, both structures loaded once) the daemon keeps its descriptors, its
threads and its memory, the renderers stay connected throughout, and the whole recording
verifies to 0 N. (A renderer rebuilds its scene at every load and settles over more
rounds than the suite can afford: `sasprobe bench soak` measures it.)"""

from __future__ import annotations

import pytest

ROUNDS = 4
# What the daemon may gain in all the rounds after the first, MB: its allocator settling
# (measured at a tenth of this over ten rounds); keeping one 1OKY engine a round would
# cost several MB a round.
SETTLING_MB = 1.0


@pytest.fixture(scope="module")
def soaked(gl, reference_by_id, crambin, tmp_path_factory):
    from sasprobe.cli.bench.soak import soak

    other = reference_by_id["1oky"].path
    structures = [("1crn.pdb.gz", crambin.source_bytes), (other.name, other.read_bytes())]
    return soak(
        tmp_path_factory.mktemp("soak"), ROUNDS, 0.0, structures, renderers=2, fault_ticks=1500
    )


def test_the_daemon_keeps_its_descriptors_threads_and_memory(soaked):
    warm = [s["daemon"] for s in soaked["samples"][1:]]
    assert len(warm) == ROUNDS - 1
    assert len({d["fds"] for d in warm}) == 1 and len({d["threads"] for d in warm}) == 1, warm
    rss = [d["rss_mb"] for d in warm]
    assert max(rss) - rss[0] <= SETTLING_MB, rss


def test_the_renderers_follow_the_whole_session(soaked):
    assert soaked["renderers_ended"] == []
    for sample in soaked["samples"]:
        assert len(sample["renderers"]) == 2 and all(r["threads"] > 1 for r in sample["renderers"])
    assert soaked["samples"][-1]["worst_pose_gap_ms"] > 0


def test_the_whole_recording_verifies_with_its_faults(soaked):
    v = soaked["verify"]
    assert v["ok"] and v["max_force_diff_n"] == 0.0 and v["flag_mismatches"] == 0
    assert v["fault_ticks"] > 0 and v["missing_ticks"] == 0
    assert v["events_applied"] >= ROUNDS * 4  # set, mark and two loads a round
    assert soaked["summary"]["ticks"] == v["ticks"] and soaked["findings"]["session"]["ticks"] > 0
    assert soaked["stopped"]["recording"]["dropped"] == 0
