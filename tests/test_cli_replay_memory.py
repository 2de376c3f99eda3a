"""Every way of reading a recording holds the same memory whatever the recording's length.

Two sessions of the simulated scan, one four times the other's ticks, are read by each
mode in this process. Small blocks of ticks, small chunks for a copy and a small path bound
make what a reader needs far smaller than either recording; the peak of the bytes Python
and numpy hold (tracemalloc: a count, not a time) on the long one stays within 1.3x of the
short one's. A reader that kept every tick, in any form, would hold about four times as
much. Each mode reads the short one once before, so that imports and first-use caches are
not counted against it.
"""

from __future__ import annotations

import gc
import tracemalloc
from pathlib import Path

import pytest
from sasprobe.daemon.service import Daemon, DaemonConfig

from sasprobe.cli.main import main
from tests.support.recordings import read_session
from tests.support.tick_driver import TickDriver

TICKS = {"short": 1_000, "long": 4_000}
BLOCK_TICKS = 128
COPY_CHUNK_BYTES = 64 << 10
MAX_POINTS = 64
PEAK_RATIO = 1.3


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("lengths")
    paths = {}
    for name, ticks in TICKS.items():
        paths[name] = folder / f"{name}.mcap"
        config = DaemonConfig(
            device="sim:scan",
            pub=[f"ipc://{folder}/p-{name}"],
            ctl=[f"ipc://{folder}/c-{name}"],
            record=str(paths[name]),
            realtime=False,
            spin_s=0,
        )
        daemon = Daemon(config)
        try:
            TickDriver(daemon, paced=True).run(ticks)
        finally:
            daemon._shutdown()
        assert read_session(paths[name]).n_ticks == ticks
    return paths


def _replay_device(path: Path, out: Path) -> None:
    daemon = Daemon(
        DaemonConfig(
            device=f"replay:{path}",
            speed=None,
            pub=[f"ipc://{out}-p"],
            ctl=[f"ipc://{out}-c"],
            realtime=False,
            spin_s=0,
        )
    )
    try:
        daemon.loop.run()  # to the end of the replay
        assert daemon.loop.stop_reason == "end of replay"
    finally:
        daemon._shutdown()


def _cli(path: Path, out: Path, *args: str) -> None:
    assert main(["replay", str(path), *args]) == 0


MODES = {
    "summary": lambda path, out: _cli(path, out),
    "verify": lambda path, out: _cli(path, out, "--verify"),
    "findings": lambda path, out: _cli(path, out, "--findings", str(out)),
    "recover": lambda path, out: _cli(path, out, "--recover", str(out) + ".mcap"),
    "video": lambda path, out: _cli(
        path, out, "--video", str(out) + ".mp4", "--fps", "2", "--size", "64x36"
    ),
    "device": _replay_device,
}


def _peak(mode: str, path: Path, out: Path) -> int:
    gc.collect()  # what earlier tests left for the collector is not this mode's
    tracemalloc.start()
    try:
        MODES[mode](path, out)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("mode", list(MODES))
def test_a_longer_recording_is_read_in_the_same_memory(
    mode, recordings, tmp_path, monkeypatch, capsys, request
):
    from sasprobe.daemon.findings import path as explored_path
    from sasprobe.protocol import recording

    if mode == "video":
        request.getfixturevalue("gl")  # a skip where no headless OpenGL context can be made
    monkeypatch.setattr(recording, "BLOCK_TICKS", BLOCK_TICKS)
    monkeypatch.setattr(recording, "COPY_CHUNK_BYTES", COPY_CHUNK_BYTES)
    monkeypatch.setattr(explored_path, "MAX_POINTS", MAX_POINTS)
    MODES[mode](recordings["short"], tmp_path / "warm")
    short = _peak(mode, recordings["short"], tmp_path / "short")
    long = _peak(mode, recordings["long"], tmp_path / "long")
    if long > PEAK_RATIO * short:
        # tracemalloc counts every thread's allocations: a thread an earlier test left running
        # can add to one measurement; a reader that keeps every tick is over it every time
        long = min(long, _peak(mode, recordings["long"], tmp_path / "long-again"))
    capsys.readouterr()
    assert long <= PEAK_RATIO * short, f"{mode}: peak {long:,} B on the long one, {short:,} B short"
