"""What a recording says about an arm that went silent: when the daemon flagged the
fault and zeroed the force, measured on the recording's own clock (the log time of each
tick, its publish time on the host's monotonic clock), and whether any tick is missing."""

from __future__ import annotations

import numpy as np
from sasprobe.protocol.pose import FLAG_FAULT

from tests.support.recordings import read_session, reference_ticks

DETECT_WITHIN_NS = 100_000_000


def recorded_outage(path, failed_at_ns: int) -> dict:
    """The first outage after `failed_at_ns` (the test's monotonic time when the arm stopped
    answering), asserted to be flagged within 100 ms of the first tick after it, with zero
    force on every faulted tick and no tick missing from the file. Returns the session, the
    outage's tick range and its read errors."""
    s = read_session(path)
    assert s.missing_ticks == 0, "the recording has holes"
    log_ns = {t["pose"]["seq"]: t["pose"]["publish_t_ns"] for t in reference_ticks(path)}
    times = np.array([log_ns[int(q)] for q in s.seq])
    after = np.flatnonzero(times > failed_at_ns)
    assert after.size, "no tick after the arm stopped answering"
    faulted = [int(i) for i in after if s.flags[i] & FLAG_FAULT]
    assert faulted, "the outage was never flagged"
    start = faulted[0]
    detect_ns = int(times[start] - times[after[0]])
    assert detect_ns <= DETECT_WITHIN_NS, (
        f"flagged {detect_ns / 1e6:.1f} ms after the first tick of the outage"
    )
    end = start
    while end < s.n_ticks and s.flags[end] & FLAG_FAULT:
        end += 1
    assert not np.any(s.force_n[start:end]), "a faulted tick wrote force"
    return {
        "session": s,
        "start": start,
        "end": end,
        "detect_ms": detect_ns / 1e6,
        "errors": [s.errors.get(i) for i in range(start, end)],
    }
