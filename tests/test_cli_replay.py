"""`sasprobe replay FILE --verify`'s line: how many of the recomputed ticks differ from the
recording, and by how much at most."""

from __future__ import annotations

from sasprobe.cli.commands.replay import verify_line

REPORT = {
    "ticks": 4000,
    "events_applied": 3,
    "max_force_diff_n": 0.0,
    "ticks_with_force_diff": 0,
    "first_diff_seq": None,
    "flag_mismatches": 0,
    "ok": True,
}


def test_an_exact_replay_says_every_tick_matched():
    line = verify_line(REPORT)
    assert "0 N on all 4000 ticks" in line and line.endswith("-> OK"), line
    assert "over 0 ticks" not in line


def test_a_different_replay_says_how_many_ticks_differ():
    line = verify_line(
        {
            **REPORT,
            "max_force_diff_n": 0.25,
            "ticks_with_force_diff": 12,
            "first_diff_seq": 1800,
            "ok": False,
        }
    )
    assert "0.25 N on 12 of 4000 ticks (the first at tick 1800)" in line, line
    assert line.endswith("-> DIFFERENT")
