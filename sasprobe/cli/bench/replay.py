"""`sasprobe bench replay`: how fast each way of reading a recording runs, and the memory it
takes, on recordings of different lengths.

Each length is a session of the simulated arm (`sasprobe daemon --device sim:scan
--record`, in real time; `--recording FILE` measures given files instead). Each mode is
one command, run as a child process: `sasprobe replay FILE` (the summary), `--verify`,
`--findings DIR`, `--recover OUT` (of the file cut in half, as a killed daemon leaves it),
`--video OUT` (small and at a low frame rate: the reading, not the drawing, is measured;
where OpenGL is missing the mode is left out) and the replay device (`sasprobe daemon
--device replay:FILE --speed max`). For each: the wall time (Python's start-up
included), the ticks and megabytes of recording per second, and the child's peak
resident memory (its rusage). Memory that does not grow with the recording's length is
the point: the table gives each mode's peak on the longest recording over its peak on
the shortest. Last, how fast the recorder's writer thread takes ticks (in this process).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sasprobe.cli.bench import BenchContext, BenchResult
from sasprobe.cli.bench.charts import pyplot, save
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress

TITLE = "Recordings: replay throughput and memory by recording length"
MODES = ("summary", "verify", "findings", "recover", "video", "device")
VIDEO = ("--size", "64x36", "--fps", "2")


def add_arguments(parser) -> None:
    from sasprobe.cli.argtypes import positive_float

    parser.add_argument(
        "--seconds",
        type=positive_float,
        action="append",
        metavar="S",
        help="record a simulated session of S seconds to measure (repeatable; default 30 and "
        "120, --quick 10 and 40)",
    )
    parser.add_argument(
        "--recording",
        type=Path,
        action="append",
        metavar="FILE",
        help="measure this recording instead (repeatable)",
    )
    parser.add_argument(
        "--modes",
        default=",".join(MODES),
        help=f"comma-separated modes to run (default all: {', '.join(MODES)})",
    )


def _sasprobe(*args: str) -> list[str]:
    return [sys.executable, "-m", "sasprobe", *args]


# A child's peak memory counts what it had before exec: a child forked from this process
# would start at this process's size. So a bare Python (no site, a few MB) starts the
# command and reports its peak on the descriptor it is given, as `/usr/bin/time` would.
_LAUNCHER = """
import os, sys
pid = os.posix_spawn(sys.argv[2], sys.argv[2:], os.environ)
_, status, usage = os.wait4(pid, 0)
os.write(int(sys.argv[1]), b"%d %d" % (os.waitstatus_to_exitcode(status), usage.ru_maxrss))
"""


def _timed(argv: list[str], log: Path) -> dict:
    """Run a child to its end: its wall time, peak resident memory (MB) and stdout."""
    read_end, write_end = os.pipe()
    with open(log, "ab") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-S", "-c", _LAUNCHER, str(write_end), *argv],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=err,
            pass_fds=(write_end,),
        )
        os.close(write_end)
        out = proc.stdout.read()
        proc.wait()
        wall = time.perf_counter() - t0
    with os.fdopen(read_end, "rb") as report:
        code, peak_kb = (int(v) for v in report.read().split())
    if code != 0:
        raise RuntimeError(f"{' '.join(argv[3:6])} exited {code} (log {log})")
    return {"wall_s": wall, "peak_rss_mb": peak_kb / 1024, "stdout": out.decode()}


def record(seconds: float, path: Path, log: Path) -> None:
    """A session of the simulated arm, `seconds` long, recorded to `path`."""
    folder = path.parent
    _timed(
        _sasprobe(
            "daemon",
            "--device",
            "sim:scan",
            "--record",
            str(path),
            "--seconds",
            f"{seconds:g}",
            "--no-realtime",
            "--pub",
            f"ipc://{folder}/pub",
            "--ctl",
            f"ipc://{folder}/ctl",
        ),
        log,
    )


def _cut_in_half(path: Path, out: Path) -> None:
    with open(path, "rb") as src, open(out, "wb") as dst:
        left = path.stat().st_size // 2
        while left > 0:
            chunk = src.read(min(left, 1 << 20))
            dst.write(chunk)
            left -= len(chunk)


def _have_gl() -> bool:
    try:
        from sasprobe.render.gl.context import create_headless_context

        create_headless_context().release()
        return True
    except Exception:
        return False


def measure(path: Path, label: str, modes: list[str], scratch: Path) -> dict:
    """Every mode on one recording."""
    log = scratch / "children.log"
    summary = json.loads(_timed(_sasprobe("replay", str(path), "--json"), log)["stdout"])["summary"]
    ticks, megabytes = summary["ticks"], path.stat().st_size / 1e6
    out = {
        "label": label,
        "file": path.name,
        "format": summary["format"],
        "ticks": ticks,
        "duration_s": summary["duration_s"],
        "megabytes": megabytes,
        "modes": {},
    }
    for mode in modes:
        work = scratch / mode
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir()
        if mode == "summary":
            argv = _sasprobe("replay", str(path), "--json")
        elif mode == "verify":
            argv = _sasprobe("replay", str(path), "--verify", "--json")
        elif mode == "findings":
            argv = _sasprobe("replay", str(path), "--findings", str(work / "f"), "--json")
        elif mode == "video":
            argv = _sasprobe("replay", str(path), "--video", str(work / "v.mp4"), *VIDEO, "--json")
        elif mode == "recover":
            half = work / "half.mcap"
            _cut_in_half(path, half)
            argv = _sasprobe("replay", str(half), "--recover", str(work / "r.mcap"), "--json")
        else:  # the replay device, as fast as the loop goes
            argv = _sasprobe(
                "daemon",
                "--device",
                f"replay:{path}",
                "--speed",
                "max",
                "--no-realtime",
                "--pub",
                f"ipc://{work}/pub",
                "--ctl",
                f"ipc://{work}/ctl",
            )
        run = _timed(argv, log)
        stdout = run.pop("stdout")
        if mode == "verify":
            run["ok"] = json.loads(stdout)["verify"]["ok"]
        elif mode == "device":
            stopped = [json.loads(x) for x in stdout.splitlines() if '"stopped"' in x]
            run["ticks"] = stopped[-1]["ticks"] if stopped else None
        share = 0.5 if mode == "recover" else 1.0  # recover reads the half it is given
        run["ticks_per_s"] = ticks * share / run["wall_s"]
        run["mb_per_s"] = megabytes * share / run["wall_s"]
        out["modes"][mode] = run
        shutil.rmtree(work, ignore_errors=True)
    return out


def recorder_throughput(ticks: int, folder: Path) -> dict:
    """How fast the recorder's writer thread takes ticks: `ticks` ticks of the simulated arm's
    shape (1024 different ones, in turn) offered at once, the queue holding them all, timed
    to the end of close(), which waits for the writer to drain the queue and finish the file."""
    import numpy as np

    from sasprobe.daemon.recording.writer import Recorder
    from sasprobe.devices.base import DeviceState
    from sasprobe.protocol.pose import Pose

    rng = np.random.default_rng(0)
    shapes = []
    for k in range(1024):
        p = rng.normal(scale=20.0, size=3)
        state = DeviceState(t_ns=k * 250_000, position_mm=p, velocity_mm_s=p * 0.1)
        pose = Pose(seq=k, publish_t_ns=k * 250_000, proxy_A=p, goal_A=p, tip_mm=p)
        shapes.append((state, pose))
    path = folder / "recorder.mcap"
    recorder = Recorder(path, {"device": "bench"}, queue_limit=ticks + 1)
    t0 = time.perf_counter()
    for seq in range(ticks):
        state, pose = shapes[seq % 1024]
        recorder.offer_tick(seq * 250_000, seq, state, None, 0.0, 20_000, pose)
    stats = recorder.close()
    wall = time.perf_counter() - t0
    path.unlink()  # its size says little: 1024 ticks repeated compress far better than a hand
    return {
        "ticks": ticks,
        "dropped": stats.dropped,
        "wall_s": wall,
        "ticks_per_s": ticks / wall,
    }


def run(ctx: BenchContext, args=None) -> BenchResult:
    given = getattr(args, "recording", None) or []
    lengths = getattr(args, "seconds", None) or (
        [1.0, 2.0] if ctx.smoke else [10.0, 40.0] if ctx.quick else [30.0, 120.0]
    )
    modes = [m for m in getattr(args, "modes", ",".join(MODES)).split(",") if m]
    unknown = sorted(set(modes) - set(MODES))
    if unknown:
        raise UserError(f"--modes: no mode {', '.join(unknown)} (modes: {', '.join(MODES)})")
    for path in given:
        if not path.is_file():
            raise UserError(f"--recording {path}: no such file")
    if "video" in modes and not _have_gl():
        modes.remove("video")
    scratch = Path(tempfile.mkdtemp(prefix="sasprobe-bench-replay-"))
    try:
        files = [(path, path.name) for path in given]
        if not given:
            for seconds in progress(lengths, desc="bench replay: recording"):
                path = scratch / f"sim-{seconds:g}s.mcap"
                record(seconds, path, scratch / "children.log")
                files.append((path, f"{seconds:g} s"))
        rows = [
            measure(path, label, modes, scratch)
            for path, label in progress(files, desc="bench replay: reading")
        ]
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    rows.sort(key=lambda r: r["ticks"])
    folder = Path(tempfile.mkdtemp(prefix="sasprobe-bench-recorder-"))
    try:
        written = recorder_throughput(5_000 if ctx.smoke else 200_000, folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    data = {
        "modes": modes,
        "recordings": rows,
        "recorder": written,
        "load_average_1min": os.getloadavg()[0],
    }
    if len(rows) > 1:
        data["peak_ratio_longest_to_shortest"] = {
            m: rows[-1]["modes"][m]["peak_rss_mb"] / rows[0]["modes"][m]["peak_rss_mb"]
            for m in modes
        }
        data["length_ratio"] = rows[-1]["ticks"] / max(rows[0]["ticks"], 1)
    charts = []
    path = ctx.chart_path("replay_memory.png")
    if path is not None:
        charts.append(_chart(rows, modes, path))
    return BenchResult("replay", data, _markdown(data, bool(given)), charts)


def _chart(rows: list[dict], modes: list[str], path: Path) -> Path:
    fig, (left, right) = pyplot().subplots(1, 2, figsize=(9.6, 3.8), dpi=110)
    for ax in (left, right):
        ax.grid(True, which="both", alpha=0.3)
    minutes = [r["duration_s"] / 60 for r in rows]
    for mode in modes:
        left.plot(minutes, [r["modes"][mode]["peak_rss_mb"] for r in rows], "o-", label=mode)
        right.plot(minutes, [r["modes"][mode]["ticks_per_s"] for r in rows], "o-", label=mode)
    left.set_xlabel("recording length (min)")
    left.set_ylabel("peak resident memory (MB)")
    left.set_ylim(bottom=0)
    left.set_title("Memory by recording length")
    right.set_xlabel("recording length (min)")
    right.set_ylabel("ticks read per second (log)")
    right.set_yscale("log")
    right.set_title("Throughput (start-up included)")
    right.legend(fontsize=7)
    return save(fig, path)


def _markdown(data: dict, given: bool) -> str:
    rows, modes = data["recordings"], data["modes"]
    source = (
        "the recordings given"
        if given
        else "sessions of the simulated arm (`sasprobe daemon --device sim:scan --record FILE`, "
        "recorded in real time at 1 kHz)"
    )
    lines = [
        "| recording | ticks | MB | mode | wall (s) | ticks/s | MB/s | peak RSS (MB) |",
        "|---|---:|---:|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        for m in modes:
            x = r["modes"][m]
            lines.append(
                f"| {r['label']}, format {r['format']} | {r['ticks']} | "
                f"{r['megabytes']:.1f} | {m}{'' if x.get('ok', True) else ' (DIFFERENT)'} | "
                f"{x['wall_s']:.1f} | {x['ticks_per_s']:.0f} | {x['mb_per_s']:.2f} | "
                f"{x['peak_rss_mb']:.0f} |"
            )
    text = [
        f"Each mode is one run of its command on {source}, as a child process: wall time "
        "with Python's start-up, ticks (and megabytes) of recording read per second of it, "
        "and the child's peak resident memory. `recover` reads the file cut in half; "
        f"`video` draws {VIDEO[1]} frames at {VIDEO[3]} fps (the reading is measured, not the "
        "drawing); `device` is the daemon on the replay device "
        "(`--device replay:FILE --speed max`). "
        f"Load average at the end: {data['load_average_1min']:.1f} on {os.cpu_count()} cores "
        "(a shared machine: times vary with it, memory does not).",
        "",
        *lines,
    ]
    w = data["recorder"]
    text += [
        "",
        f"The recorder: {w['ticks']:,} ticks of the simulated arm's shape offered at once, "
        f"written by its thread in {w['wall_s']:.1f} s: {w['ticks_per_s']:,.0f} ticks/s "
        f"({w['dropped']} dropped); a loop at 4 kHz uses {400000 / w['ticks_per_s']:.0f} % "
        "of that.",
    ]
    if "peak_ratio_longest_to_shortest" in data:
        ratios = ", ".join(
            f"{m} {v:.2f}" for m, v in data["peak_ratio_longest_to_shortest"].items()
        )
        text += [
            "",
            f"Peak memory on the longest recording over the shortest ({data['length_ratio']:.1f} "
            f"times the ticks): {ratios}.",
        ]
    return "\n".join(text)
