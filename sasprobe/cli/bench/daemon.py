"""`sasprobe bench daemon`: loop timing, publish→receive latency, drops and CPU of a real daemon.

Each configuration starts `sasprobe daemon` as a subprocess on the simulated arm
(scan script) publishing on both a loopback TCP and an ipc:// endpoint. After a
warm-up the daemon's statistics are reset; for the measured window this process
subscribes on both endpoints from one thread (timestamping each message as it is
received) and at the end asks the daemon for its loop figures (`status`).
Publish→receive latency compares the pose's publish_t_ns with the receive time on the
same host's monotonic clock. Then one row per emulated device (`daemon_devices`), and
the worst pose gap while a client loads the largest reference structure, 6ZU5
(`daemon_loading`).
"""

from __future__ import annotations

import os
import shutil
import socket
import tempfile
import time
from pathlib import Path

import numpy as np

from sasprobe.cli.bench import BenchContext, BenchResult, daemon_devices
from sasprobe.cli.bench.charts import figure, save
from sasprobe.cli.children import DaemonChild
from sasprobe.cli.reference_data import reference_structures
from sasprobe.common.progress import progress

TITLE = "Device daemon: loop timing, latency, drops, CPU"
READY_S = 90.0  # start-up on a loaded machine: imports, structure, grid
STOP_S = 30.0
TARGETS = (
    "1000 Hz, p99 period error ≤ 200 µs, no overrun in "
    "10 s with ~60k atoms, latency p99 ≤ 1 ms, no drops"
)


def add_arguments(parser) -> None:
    from sasprobe.cli.argtypes import positive_float

    parser.add_argument(
        "--seconds", type=float, default=None, help="measured window per run (default 10, quick 3)"
    )
    parser.add_argument(
        "--no-realtime",
        action="store_true",
        help="skip the real-time (SCHED_FIFO, the default) runs: only --no-realtime daemons",
    )
    parser.add_argument(
        "--no-devices", action="store_true", help="skip the rows on the emulated devices"
    )
    parser.add_argument(
        "--device-rate",
        type=positive_float,
        action="append",
        metavar="HZ",
        help="run each emulated device's row at this loop rate (repeatable; default: the rate "
        "each device declares)",
    )


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _Daemon:
    def __init__(self, molecule: Path | None, realtime: bool) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="spb"))
        self.tcp = f"tcp://127.0.0.1:{_free_port()}"
        self.ipc = f"ipc://{self.dir}/pub"
        self.ctl = f"ipc://{self.dir}/ctl"
        args = ["--device", "sim", "--pub", self.tcp, "--pub", self.ipc, "--ctl", self.ctl]
        if molecule is not None:
            args += ["--molecule", str(molecule)]
        if not realtime:
            args.append("--no-realtime")
        self.child = DaemonChild(args, self.dir / "daemon.log")
        try:
            self.ready = self.child.wait_ready(READY_S)
        except BaseException:
            self.stop()
            raise

    def stop(self) -> None:
        self.child.stop(STOP_S)
        shutil.rmtree(self.dir, ignore_errors=True)


def _measure(d: _Daemon, warmup_s: float, seconds: float, realtime_subscriber: bool) -> dict:
    import zmq

    from sasprobe.daemon.realtime import enter_realtime
    from sasprobe.protocol.client import ControlClient
    from sasprobe.protocol.pose import decode_pose
    from sasprobe.protocol.security import local_client_keys, make_curve_client

    # The daemon is already running, so it does not inherit this; the context's I/O thread does.
    subscriber_rt = enter_realtime(priority=40) if realtime_subscriber else False
    context = zmq.Context()
    socks = {}
    # the publisher binds loopback TCP, so it uses CURVE (ipc:// on it too)
    keys = local_client_keys()
    for name, endpoint in (("tcp", d.tcp), ("ipc", d.ipc)):
        sock = context.socket(zmq.SUB)
        make_curve_client(sock, keys)
        sock.rcvhwm = 1_000_000
        sock.setsockopt(zmq.SUBSCRIBE, b"pose")
        sock.connect(endpoint)
        socks[sock] = name
    poller = zmq.Poller()
    for sock in socks:
        poller.register(sock, zmq.POLLIN)
    latencies = {"tcp": [], "ipc": []}
    seqs = {"tcp": [], "ipc": []}
    clock = time.monotonic_ns
    with ControlClient(d.ctl, timeout_s=10) as client:
        end_warmup = time.monotonic() + warmup_s
        while time.monotonic() < end_warmup:  # drain while warming up
            for sock, _ in poller.poll(50):
                while sock.poll(0):
                    sock.recv_multipart()
        client.status(reset_stats=True)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for sock, _ in poller.poll(50):
                name = socks[sock]
                while True:
                    try:
                        frames = sock.recv_multipart(zmq.NOBLOCK)
                    except zmq.Again:
                        break
                    now = clock()
                    pose = decode_pose(frames[1])
                    latencies[name].append(now - pose.publish_t_ns)
                    seqs[name].append(pose.seq)
        status = client.status()
    for sock in socks:
        sock.close(linger=0)
    context.term()
    if subscriber_rt:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    out = {
        "loop": status["loop"],
        "device": status["device"]["model"],
        "structure": status["structure"],
        "subscriber_realtime": subscriber_rt,
    }
    for name in ("tcp", "ipc"):
        lat = np.array(latencies[name], dtype=np.float64) / 1e3
        s = np.array(seqs[name])
        drops = int((s[-1] - s[0] + 1) - np.unique(s).size) if s.size else None
        out[name] = {
            "received": int(s.size),
            "drops": drops,
            "latency_us": {
                "p50": float(np.percentile(lat, 50)) if lat.size else None,
                "p99": float(np.percentile(lat, 99)) if lat.size else None,
                "max": float(lat.max()) if lat.size else None,
            },
            "samples_us": lat,
        }
    return out


def run(ctx: BenchContext, args=None) -> BenchResult:
    seconds = getattr(args, "seconds", None) or (0.5 if ctx.smoke else 3.0 if ctx.quick else 10.0)
    # (daemon real-time, subscriber in SCHED_FIFO): where the time goes on a busy machine
    modes = (
        [(False, False)]
        if getattr(args, "no_realtime", False) or ctx.smoke
        else [(False, False), (True, False), (True, True)]
    )
    entries = reference_structures()
    by_id = {e.id: e for e in entries}
    structures = [("1crn (embedded)", None)]
    if "1aon" in by_id and not ctx.smoke:
        structures.append(("1aon", by_id["1aon"].path))
    runs = []
    configs = [(label, path, rt, sub_rt) for label, path in structures for rt, sub_rt in modes]
    for label, path, realtime, sub_rt in progress(configs, desc="bench daemon", total=len(configs)):
        d = _Daemon(path, realtime)
        try:
            result = _measure(d, warmup_s=1.5, seconds=seconds, realtime_subscriber=sub_rt)
        finally:
            d.stop()
        result.update(
            label=label,
            realtime_requested=realtime,
            realtime=bool(d.ready.get("realtime")),
            seconds=seconds,
            load_average_1min=os.getloadavg()[0],
        )
        runs.append(result)
    charts = []
    path = ctx.chart_path("daemon_latency.png")
    if path is not None:
        fig, ax = figure()
        largest = runs[-1]["label"]  # the chart shows the largest structure (the target case)
        colors = iter(["tab:red", "tab:blue", "tab:green", "tab:purple"])
        for r in (r for r in runs if r["label"] == largest):
            color = next(colors)
            for name, style in (("tcp", "-"), ("ipc", "--")):
                lat = np.sort(r[name]["samples_us"])
                if lat.size:
                    ax.semilogx(
                        lat,
                        np.arange(1, lat.size + 1) / lat.size,
                        style,
                        color=color,
                        label=f"{_mode(r)}, {name}",
                    )
        ax.axvline(1000, color="k", ls=":", lw=1)
        ax.set_xlabel("publish → receive latency (µs)")
        ax.set_ylabel("fraction of poses")
        ax.set_title(f"Pose latency over loopback, {largest} (CDF); dotted: 1 ms target")
        ax.legend(fontsize=7)
        charts.append(save(fig, path))
    for r in runs:
        for name in ("tcp", "ipc"):
            r[name].pop("samples_us")
    data, text = {"targets": TARGETS, "runs": runs}, _markdown(runs, seconds)
    if not getattr(args, "no_devices", False):
        rates = getattr(args, "device_rate", None)
        data["devices"] = daemon_devices.measure(seconds, smoke=ctx.smoke, rates_hz=rates)
        text += "\n\n" + daemon_devices.markdown(data["devices"])
    # the worst pose gap under a client loading the largest structure (--smoke: the smallest)
    if entries:
        from sasprobe.cli.bench.daemon_loading import loading_gap, markdown
        from sasprobe.molecule import load_default

        big = entries[0] if ctx.smoke else entries[-1]
        data["loading"] = loading_gap(big.path, load_default().source_bytes, seconds) | {
            "id": big.id
        }
        text += markdown(data["loading"], big.id.upper())
    return BenchResult("daemon", data, text, charts)


def _mode(r: dict) -> str:
    daemon = (
        "FIFO"
        if r["realtime"]
        else ("normal (FIFO refused)" if r["realtime_requested"] else "normal")
    )
    return f"daemon {daemon} / subscriber {'FIFO' if r['subscriber_realtime'] else 'normal'}"


def _fmt(v, digits=0) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def _markdown(runs: list[dict], seconds: float) -> str:
    lines = [
        "| structure | atoms | scheduling | rate (Hz) | period error p50 / p99 / max (µs) | "
        "overruns (missed ticks) | tick work p50 / p99 (µs) | loop CPU | latency tcp p50 / p99 "
        "(µs) | latency ipc p50 / p99 (µs) | drops tcp / ipc | load avg |",
        "|---|---:|---|---:|---|---|---|---:|---|---|---|---:|",
    ]
    for r in runs:
        loop, err, work = r["loop"], r["loop"]["period_error_us"], r["loop"]["work_us"]
        lines.append(
            f"| {r['label']} | {r['structure']['n_atoms']} | {_mode(r)} | "
            f"{_fmt(loop['rate_hz'], 1)} | {_fmt(err['p50'])} / {_fmt(err['p99'])} / "
            f"{_fmt(err['max'])} | {loop['overruns']} ({loop['missed_deadlines']}) | "
            f"{_fmt(work['recent_p50'])} / {_fmt(work['recent_p99'])} | "
            f"{_fmt(loop['cpu_percent'])} % | {_fmt(r['tcp']['latency_us']['p50'])} / "
            f"{_fmt(r['tcp']['latency_us']['p99'])} | {_fmt(r['ipc']['latency_us']['p50'])} / "
            f"{_fmt(r['ipc']['latency_us']['p99'])} | {r['tcp']['drops']} / {r['ipc']['drops']} | "
            f"{r['load_average_1min']:.1f} |"
        )
    return (
        f"Each row: `sasprobe daemon --device sim` at 1000 Hz for {seconds:g} s after a 1.5 s "
        "warm-up, publishing on loopback TCP and ipc:// at once, one subscriber per transport in "
        "the benchmark process. Period error is |interval between tick starts − 1 ms| (1 µs "
        "bins); an overrun is a tick that started a full period late (the deadlines it skipped "
        "are the missed ticks); tick work is read + haptics + write + publish (last ~1000 "
        "ticks); loop CPU is the loop thread's CPU time over wall time; load avg is the "
        f"machine's 1-minute load average at the end of the run ({os.cpu_count()} cores, shared "
        "with other work). Scheduling: daemon `FIFO` is its default (SCHED_FIFO for its loop; "
        "ZeroMQ's I/O thread stays at normal priority), `normal` is `--no-realtime`; subscriber "
        "`FIFO` puts the benchmark's receiving thread in SCHED_FIFO as well, which shows how "
        "much of the latency is the receiver waiting for a core. "
        f"Targets: {TARGETS}.\n\n" + "\n".join(lines)
    )
