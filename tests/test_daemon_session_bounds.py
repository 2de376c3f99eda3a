"""A session that does not grow, by counts: what the daemon keeps after ten thousand ticks
(with device faults, a device that stops answering and refused marks) and after hundreds
of refused connections is what it kept before them. docs/daemon.md ("What a session
keeps") lists each structure and its bound.

The daemon runs in this process and the test runs its ticks itself, one call a tick, so the
counts do not depend on the machine's speed. Growth is measured as the entries of every
list, dict, set and deque the collector sees (a structure that keeps something per tick or
per connection adds at least one each time) and as the bytes tracemalloc sees allocated and
still held.
"""

from __future__ import annotations

import collections
import gc
import logging
import os
import threading
import time
import tracemalloc

import pytest
import zmq
from sasprobe.daemon.marks import drop_mark
from sasprobe.daemon.service import Daemon, DaemonConfig
from sasprobe.daemon.timer import RECENT_TICKS
from sasprobe.protocol.scene import MAX_MARKS

from sasprobe.common.errors import UserError
from tests.support.daemon_process import free_tcp_endpoint
from tests.support.tick_driver import TickDriver

WARM_TICKS = 3_000
MEASURED_TICKS = 10_000
# Faults on the simulated arm while measured: non-finite readings, a driver exception, and a
# device that stops answering long enough to be reconnected.
FAULTS = ["nan@4000+5", "raise@6000+40", "disconnect@9500+300"]
REFUSED_ROUNDS, REFUSED_PER_ROUND = 5, 60


def container_entries() -> int:
    gc.collect()
    kinds = (list, dict, set, collections.deque)
    return sum(len(o) for o in gc.get_objects() if isinstance(o, kinds))


def _recorder_drained(daemon: Daemon) -> bool:
    return not daemon.recorder._queue and not daemon.recorder._packer.count


def _recorder_settled(daemon: Daemon) -> None:
    """No tick running, the recorder's queue written out and a chunk ended since (the open
    chunk holds an index entry per message: how many depends on how the writer thread was
    scheduled, not on what the session keeps)."""
    recorder = daemon.recorder
    deadline = time.monotonic() + 60.0
    while not _recorder_drained(daemon):
        assert time.monotonic() < deadline, "the recorder's queue did not drain"
        time.sleep(0.01)
    ended = recorder.flushes + 2  # the flush under way may have begun before the last write
    while recorder.flushes < ended:
        assert time.monotonic() < deadline, "the recorder ended no chunk"
        time.sleep(0.01)


@pytest.fixture
def quiet():
    logger = logging.getLogger("sasprobe")
    level = logger.level
    logger.setLevel(logging.ERROR)  # one warning a second per fault otherwise
    yield
    logger.setLevel(level)


def test_a_recording_session_keeps_the_same_after_10000_more_ticks(tmp_path, quiet):
    daemon = Daemon(
        DaemonConfig(
            pub=[f"ipc://{tmp_path}/p"],
            ctl=[f"ipc://{tmp_path}/c"],
            record=str(tmp_path / "session.mcap"),
            realtime=False,
            spin_s=0,
            faults=FAULTS,
        )
    )
    refused = []

    def mark(seq: int) -> None:
        try:
            drop_mark(daemon, seq, None, "test")
        except UserError as exc:
            refused.append(str(exc))

    driver = TickDriver(daemon)
    try:
        driver.run(WARM_TICKS, every=5, action=mark)  # 600 marks asked for: MAX_MARKS kept
        assert len(daemon.marks.scene(daemon.structure.sha256)) == MAX_MARKS
        _recorder_settled(daemon)
        entries = container_entries()
        tracemalloc.start()
        try:
            driver.run(MEASURED_TICKS, every=100, action=mark)
            _recorder_settled(daemon)
            grown_entries = container_entries() - entries
            held_bytes = tracemalloc.get_traced_memory()[0]
        finally:
            tracemalloc.stop()
        timing = daemon.loop.timing
        stats = daemon.loop.stats
        recorder = daemon.recorder
        assert len(refused) == 600 - MAX_MARKS + MEASURED_TICKS // 100
        assert len(daemon.marks.scene(daemon.structure.sha256)) == MAX_MARKS
        assert daemon.pipeline.guard.faulted is False
        assert len(stats.recent) == len(stats.recent_work) == RECENT_TICKS
        assert len(timing._window) <= 1 and not daemon.changes._pending
        assert recorder.dropped == 0 and len(recorder._attached) == 1
        # the MCAP writer's chunk index: one entry per flush, in a file, none in memory
        assert recorder._writer._Writer__chunk_indices is recorder._chunk_indexes
        flushes = recorder.flushes
        # 10,000 ticks keeping anything would add 10,000 entries; a few come and go
        assert grown_entries < 200, f"{grown_entries} entries more after {MEASURED_TICKS} ticks"
        assert held_bytes < 128 * 1024, f"{held_bytes} bytes still held after the ticks"
    finally:
        daemon.request_stop("test over")
        daemon._shutdown()
    assert flushes > 0  # chunks were written while measured, their index entries spilled


def _open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def _refused_client(context: zmq.Context, kind: int, endpoint: str) -> zmq.Socket:
    """A client without the daemon's keys, connecting once (no reconnection)."""
    sock = context.socket(kind)
    sock.linger = 0
    sock.setsockopt(zmq.RECONNECT_IVL, -1)
    if kind == zmq.SUB:
        sock.setsockopt(zmq.SUBSCRIBE, b"")
    sock.connect(endpoint)
    return sock


def test_refused_connections_leave_nothing_behind(tmp_path, monkeypatch, quiet):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))  # local keys: CURVE on loopback
    daemon = Daemon(
        DaemonConfig(pub=[free_tcp_endpoint()], ctl=[free_tcp_endpoint()], realtime=False, spin_s=0)
    )
    publisher, control = daemon.publisher, daemon.control
    pub_monitor, ctl_monitor = publisher._monitor, control._monitor
    context = zmq.Context()
    # the clients share this process: their context's own descriptors (its I/O thread's) open
    # before the count
    context.socket(zmq.SUB).close()
    driver = TickDriver(daemon)
    try:
        assert pub_monitor.curve and ctl_monitor.curve
        control.start()  # its thread drains the control socket's connection events
        per_kind = REFUSED_PER_ROUND // 2
        refused = 0

        def refuse_a_round() -> None:
            nonlocal refused
            clients = [
                _refused_client(context, kind, endpoint)
                for kind, endpoint in ((zmq.SUB, publisher.endpoints[0]),) * per_kind
                + ((zmq.REQ, control.endpoints[0]),) * per_kind
            ]
            refused += per_kind
            driver.until(
                lambda: (
                    pub_monitor.failed_handshakes >= refused
                    and ctl_monitor.failed_handshakes >= refused
                ),
                f"{refused} refused handshakes counted on each socket",
            )
            for sock in clients:
                sock.close()
            driver.until(
                lambda: pub_monitor.peers == 0 and ctl_monitor.peers == 0,
                f"after {refused} refused on each socket: no peer left",
            )

        refuse_a_round()  # what is made once (a log line's bookkeeping, first-use caches)
        fds, threads = _open_fds(), threading.active_count()
        entries = container_entries()
        for _ in range(REFUSED_ROUNDS):
            refuse_a_round()
        driver.until(lambda: _open_fds() <= fds, f"descriptors back to {fds} ({_open_fds()})")
        assert threading.active_count() == threads
        grown = container_entries() - entries
        assert grown < 100, f"{grown} entries more after {2 * REFUSED_ROUNDS * per_kind} refused"
    finally:
        context.destroy(linger=0)
        daemon.request_stop("test over")
        daemon._shutdown()
