"""`sasprobe bench soak [--minutes M]`: a whole session for as long as asked, and what the
processes keep minute by minute.

A daemon on the simulated arm (scan script) records the session and has a device fault
injected every FAULT_TICKS ticks (about 20 s at 1 kHz; in turn a failed read, non-finite
readings, a lost link, slow reads and a stalled loop); two headless renderers follow it
(`sasprobe render --connect --headless`, small frames paced at a few per second); this
process subscribes for the whole run (the worst gap between consecutive poses, on the
daemon's clock) and in each round (a minute; the suite's version runs them unpaced) lets
subscribers join and leave, and a control client asks for the status, sets the
stiffness, drops a mark and loads the two structures by their bytes in turn, ending on
the first. After each round, once the loop has run on past the last load: the daemon's
and each renderer's resident memory, descriptors and threads (from /proc), the daemon's
tick rate, overruns and lost ticks over the round, the worst pose gap and the
recording's size. At the end the daemon is shut down and `sasprobe replay FILE --verify`
and `--findings DIR` run on the whole recording.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from sasprobe.cli.bench import BenchContext, BenchResult
from sasprobe.cli.bench.charts import pyplot, save
from sasprobe.cli.bench.replay import _sasprobe, _timed
from sasprobe.cli.children import Child, DaemonChild, child_env
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress_bar

TITLE = "Long session: memory, descriptors and threads round by round"
FAULT_TICKS = 20_000
FAULTS = ("raise@{}+30", "nan@{}+20", "disconnect@{}", "slow@{}+5", "stall@{}+40")
JOINS_PER_ROUND = 12  # subscribers that join and leave in a round (every 5 s in a minute's)
SETTLE_TICKS = 2000  # ticks the loop runs after a round's last load before the sample
RENDER_SIZE, RENDER_FPS = "160x90", 4
READY_S, STOP_S, CALL_S = 120.0, 60.0, 120.0


def add_arguments(parser) -> None:
    from sasprobe.cli.argtypes import positive_float

    parser.add_argument(
        "--minutes",
        type=positive_float,
        default=None,
        help="how long the session runs, a round a minute (default 60, --quick 10)",
    )


def _proc(pid: int) -> dict:
    """Resident memory (MB), open descriptors and threads of a live process."""
    status = Path(f"/proc/{pid}/status").read_text()
    rss_kb = next(int(line.split()[1]) for line in status.splitlines() if line.startswith("VmRSS"))
    return {
        "rss_mb": rss_kb / 1024,
        "fds": len(os.listdir(f"/proc/{pid}/fd")),
        "threads": len(os.listdir(f"/proc/{pid}/task")),
    }


class _PoseWatch:
    """A subscriber for the whole session: the longest gap between consecutive poses (their
    publish times, the daemon's clock) since it was last asked."""

    def __init__(self, pub: str) -> None:
        import zmq

        self._sock = zmq.Context.instance().socket(zmq.SUB)
        self._sock.rcvhwm = 100_000
        self._sock.setsockopt(zmq.SUBSCRIBE, b"pose")
        self._sock.connect(pub)
        self._lock = threading.Lock()
        self._worst_ns = 0
        self.poses = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="soak-poses", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from sasprobe.protocol.pose import decode_pose

        last = None
        while not self._stop.is_set():
            if not self._sock.poll(100):
                continue
            pose = decode_pose(self._sock.recv_multipart()[1])
            self.poses += 1
            if last is not None and pose.seq == last[0] + 1:
                with self._lock:
                    self._worst_ns = max(self._worst_ns, pose.publish_t_ns - last[1])
            last = (pose.seq, pose.publish_t_ns)

    def take_worst_ms(self) -> float:
        with self._lock:
            worst, self._worst_ns = self._worst_ns, 0
        return worst / 1e6

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._sock.close(linger=0)


def _join_and_leave(pub: str) -> None:
    """A subscriber that connects, waits for a pose (a few seconds at most) and leaves."""
    import zmq

    sock = zmq.Context.instance().socket(zmq.SUB)
    try:
        sock.setsockopt(zmq.SUBSCRIBE, b"")
        sock.connect(pub)
        sock.poll(3000)
    finally:
        sock.close(linger=0)


@dataclass
class Soak:
    """A daemon, its renderers and this process's clients, in a scratch folder."""

    folder: Path
    structures: list[tuple[str, bytes]]  # (name, file bytes): loaded in turn, the first last
    renderers: int = 2
    fault_ticks: int = FAULT_TICKS
    faults: int = 200
    seconds: float = 3600.0  # how long the renderers may run
    samples: list[dict] = field(default_factory=list)
    ended: list[dict] = field(default_factory=list)  # renderers that ended before the soak did

    def start(self) -> None:
        from sasprobe.protocol.client import ControlClient

        self.recording = self.folder / "soak.mcap"
        self.pub, self.ctl = f"ipc://{self.folder}/pub", f"ipc://{self.folder}/ctl"
        faults = []
        for k in range(self.faults):
            faults += ["--inject-fault", FAULTS[k % len(FAULTS)].format((k + 1) * self.fault_ticks)]
        self.daemon = DaemonChild(
            ["--device", "sim:scan", "--record", str(self.recording)]
            + ["--pub", self.pub, "--ctl", self.ctl, *faults],
            self.folder / "daemon.log",
        )
        self.children: list[Child] = [self.daemon]
        if self.daemon.wait_event("ready", READY_S) is None:
            raise UserError(f"the daemon did not start: {self.daemon.error_line()}")
        self.client = ControlClient(self.ctl, timeout_s=CALL_S)
        env = dict(child_env(), LP_NUM_THREADS="1")  # Mesa llvmpipe: one thread each
        self.render = []
        for k in range(self.renderers):
            argv = _sasprobe(
                "render",
                "--connect",
                self.pub,
                "--control",
                self.ctl,
                "--headless",
                "--size",
                RENDER_SIZE,
                "--fps",
                str(RENDER_FPS),
                "--seconds",
                f"{self.seconds:g}",
                "--out",
                str(self.folder / f"render{k}.mp4"),
            )
            child = Child(f"render{k}", argv, self.folder / f"render{k}.log", env=env)
            self.children.append(child)
            self.render.append(child)
        self.watch = _PoseWatch(self.pub)
        deadline = time.monotonic() + READY_S  # the renderers started and following
        while self._loop_counts()["subscribers"] < self.renderers + 1:
            if time.monotonic() > deadline or not all(r.alive() for r in self.render):
                raise UserError(
                    "the renderers did not connect: "
                    + "; ".join(r.error_line() for r in self.render)
                )
            time.sleep(0.2)
        self._last = self._loop_counts()
        self._last_t = time.monotonic()

    def _loop_counts(self) -> dict:
        status = self.client.status()
        loop = status["loop"]["total"]
        return {
            "ticks": loop["ticks"],
            "overruns": loop["overruns"],
            "lost": status["loop"]["lost_ticks"],
            "faults": status["device"]["faults"],
            "recording_mb": (status["recording"] or {}).get("bytes", 0) / 1e6,
            "subscribers": status["publisher"]["subscribers"],
        }

    def _wait_ticks(self, ticks: int) -> None:
        """Until the loop has run `ticks` more ticks (a count, whatever the machine's speed)."""
        target = self._loop_counts()["ticks"] + ticks
        deadline = time.monotonic() + CALL_S
        while self._loop_counts()["ticks"] < target:
            if time.monotonic() > deadline:
                raise RuntimeError("the daemon's loop stopped ticking")
            time.sleep(0.05)

    def round(self, index: int, pace_s: float) -> dict:
        """One round of clients, spread over pace_s, then a sample."""
        c = self.client
        join = lambda: _join_and_leave(self.pub)  # noqa: E731
        control = [
            c.status,
            lambda: c.set(stiffness_n_per_mm=0.25 if index % 2 else 0.3),
            lambda: c.mark(f"round {index}"),
            *[
                (lambda data=data, name=name: c.load(data=data, name=name, timeout_s=CALL_S))
                for name, data in (*self.structures[1:], self.structures[0])
            ],
        ]
        per = JOINS_PER_ROUND // len(control)  # the control calls spread among the joins
        actions = []
        for call in control:
            actions += [join] * per + [call]
        actions += [join] * (JOINS_PER_ROUND - per * len(control)) + [c.status]
        start = time.monotonic()
        for k, action in enumerate(actions):
            wait = start + k * pace_s / len(actions) - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            action()
        self._wait_ticks(SETTLE_TICKS)  # the last load applied, the replaced engine let go
        self._check_alive()
        counts, now = self._loop_counts(), time.monotonic()
        elapsed = now - self._last_t
        sample = {
            "round": index,
            "t_s": now - self._start,
            "daemon": _proc(self.daemon.pid),
            "renderers": [_proc(r.pid) if r.alive() else None for r in self.render],
            "tick_rate_hz": (counts["ticks"] - self._last["ticks"]) / elapsed,
            "overruns": counts["overruns"] - self._last["overruns"],
            "lost_ticks": counts["lost"] - self._last["lost"],
            "guard_faults": counts["faults"],
            "worst_pose_gap_ms": self.watch.take_worst_ms(),
            "recording_mb": counts["recording_mb"],
            "joined": JOINS_PER_ROUND,
        }
        self._last, self._last_t = counts, now
        self.samples.append(sample)
        return sample

    def _check_alive(self) -> None:
        """A daemon that ended ends the soak; a renderer that ended is noted, and the rounds
        go on without it."""
        if not self.daemon.alive():
            raise RuntimeError(f"the daemon ended: {self.daemon.error_line()}")
        for k, child in enumerate(self.render):
            if not child.alive() and all(e["renderer"] != k + 1 for e in self.ended):
                self.ended.append(
                    {
                        "renderer": k + 1,
                        "round": len(self.samples) + 1,
                        "why": child.error_line(),
                        "log_path": str(child.log_path),
                    }
                )

    def run(self, rounds: int, pace_s: float, bar=None) -> None:
        self._start = time.monotonic()
        for index in range(rounds):
            self._check_alive()
            self.round(index, pace_s)
            if bar is not None:
                bar.update(1)

    def stop(self) -> dict:
        """Shut everything down; the daemon's exit report."""
        self.watch.close()
        for child in self.render:
            child.signal(2)  # SIGINT: the renderer finishes its video
        for child in self.render:
            child.finish(STOP_S)
        try:
            self.client.call("shutdown", timeout_s=CALL_S)
        finally:
            self.client.close()
        self.daemon.finish(STOP_S)
        return self.daemon.events.get("stopped", {})

    def kill(self) -> None:
        for child in self.children:
            child.kill_group()


def check_recording(recording: Path, folder: Path) -> dict:
    """`replay --verify` and `--findings` on the whole recording: results, time, peak memory."""
    log = folder / "replay.log"
    verify = _timed(_sasprobe("replay", str(recording), "--verify", "--json"), log)
    found = _timed(
        _sasprobe("replay", str(recording), "--findings", str(folder / "findings"), "--json"), log
    )
    result = json.loads(verify.pop("stdout"))
    findings = json.loads(found.pop("stdout"))["findings"]
    return {
        "summary": result["summary"],
        "verify": {**result["verify"], **verify},
        "findings": {
            "bottleneck_A": (findings["bottleneck"] or {}).get("radius_A"),
            "session": findings["session"],
            **found,
        },
    }


def soak(
    folder: Path,
    rounds: int,
    pace_s: float,
    structures: list[tuple[str, bytes]],
    renderers: int = 2,
    fault_ticks: int = FAULT_TICKS,
) -> dict:
    """A whole soak: its samples, the daemon's exit report and the recording's checks."""
    total_s = rounds * pace_s + 600.0
    s = Soak(
        folder,
        structures,
        renderers,
        fault_ticks,
        faults=max(1, int(total_s * 1000 / fault_ticks)),
        seconds=total_s,
    )
    bar = progress_bar(rounds, desc="bench soak", unit="round")
    try:
        s.start()
        s.run(rounds, pace_s, bar)
        stopped = s.stop()
    except BaseException:
        s.kill()
        raise
    finally:
        bar.close()
    return {
        "samples": s.samples,
        "renderers_ended": s.ended,
        "stopped": stopped,
        **check_recording(s.recording, folder),
    }


def _structures(smoke: bool) -> list[tuple[str, bytes]]:
    from sasprobe.cli.reference_data import reference_structures
    from sasprobe.molecule import load_default

    first = ("1crn.pdb.gz", load_default().source_bytes)
    wanted = "1crn" if smoke else "1aon"
    other = [e for e in reference_structures() if e.id == wanted]
    if not other:
        raise UserError(f"the reference structure {wanted.upper()} is not here (tests/data/pdb)")
    return [first, (other[0].path.name, other[0].path.read_bytes())]


def run(ctx: BenchContext, args=None) -> BenchResult:
    minutes = getattr(args, "minutes", None) or (2 if ctx.smoke else 10 if ctx.quick else 60)
    rounds, pace_s = (2, 0.0) if ctx.smoke else (max(1, round(minutes)), 60.0)
    folder = Path(tempfile.mkdtemp(prefix="sasprobe-soak-"))
    try:
        data = soak(folder, rounds, pace_s, _structures(ctx.smoke))
        for ended in data["renderers_ended"]:  # its whole log, beside the charts
            log_path = ended.pop("log_path")  # in the folder about to go
            kept = ctx.chart_path(f"soak-renderer{ended['renderer']}.log")
            if kept is not None:
                shutil.copyfile(log_path, kept)
                ended["log"] = kept.name
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    data.update(
        rounds=rounds,
        round_s=pace_s,
        load_average_1min=os.getloadavg()[0],
        flat=flatness(data["samples"]),
    )
    charts = []
    path = ctx.chart_path("soak.png")
    if path is not None:
        charts.append(_chart(data["samples"], path))
    return BenchResult("soak", data, _markdown(data), charts)


def flatness(samples: list[dict], reference_round: int = 5) -> dict:
    """Each process's memory at the end over its memory at the reference round (the fifth
    minute, or the first round where the run is shorter), and whether descriptors and
    threads stayed what they were then."""
    ref = samples[min(reference_round, len(samples)) - 1]
    last = samples[-1]
    later = samples[samples.index(ref) :]
    out = {"reference_round": ref["round"] + 1}
    names = ["daemon"] + [f"renderer {k + 1}" for k in range(len(ref["renderers"]))]
    for k, name in enumerate(names):
        pick = (lambda s: s["daemon"]) if k == 0 else (lambda s, k=k: s["renderers"][k - 1])
        if any(pick(s) is None for s in later):
            out[name] = None  # it ended before the soak did
            continue
        out[name] = {
            "rss_ratio": pick(last)["rss_mb"] / pick(ref)["rss_mb"],
            "rss_max_ratio": max(pick(s)["rss_mb"] for s in later) / pick(ref)["rss_mb"],
            "fds": sorted({pick(s)["fds"] for s in later}),
            "threads": sorted({pick(s)["threads"] for s in later}),
        }
    return out


def _get(process: dict | None, key: str) -> float:
    return float("nan") if process is None else process[key]


def _chart(samples: list[dict], path: Path) -> Path:
    fig, (mem, counts, loop) = pyplot().subplots(3, 1, figsize=(8.0, 8.4), dpi=110, sharex=True)
    x = [s["t_s"] / 60 for s in samples]
    mem.plot(x, [s["daemon"]["rss_mb"] for s in samples], "o-", color="tab:red", label="daemon")
    for k in range(len(samples[0]["renderers"])):
        mem.plot(
            x,
            [_get(s["renderers"][k], "rss_mb") for s in samples],
            "s-",
            ms=3,
            label=f"renderer {k + 1}",
        )
    mem.set_ylabel("resident memory (MB)")
    mem.set_ylim(bottom=0)
    mem.legend(fontsize=7, loc="lower right")
    mem.set_title("A session with renderers, subscribers, loads and faults")
    for key, style in (("fds", "-"), ("threads", "--")):
        counts.plot(
            x, [s["daemon"][key] for s in samples], style, color="tab:red", label=f"daemon {key}"
        )
        for k in range(len(samples[0]["renderers"])):
            counts.plot(
                x,
                [_get(s["renderers"][k], key) for s in samples],
                style,
                label=f"renderer {k + 1} {key}",
            )
    counts.set_ylabel("descriptors, threads")
    counts.set_ylim(bottom=0)
    counts.legend(fontsize=6, ncol=3, loc="lower right")
    loop.plot(x, [s["tick_rate_hz"] for s in samples], "o-", color="tab:blue", label="tick rate")
    loop.set_ylabel("ticks per second", color="tab:blue")
    loop.set_ylim(bottom=0)
    gap = loop.twinx()
    gap.plot(x, [s["worst_pose_gap_ms"] for s in samples], "^-", color="tab:orange")
    gap.set_ylabel("worst pose gap (ms)", color="tab:orange")
    gap.set_yscale("log")
    loop.set_xlabel("minutes")
    for ax in (mem, counts, loop):
        ax.grid(True, alpha=0.3)
    return save(fig, path)


def _markdown(data: dict) -> str:
    samples = data["samples"]
    n = len(samples[0]["renderers"])
    head = (
        "| round | min | daemon MB | fds | threads | "
        + " | ".join(f"renderer {k + 1} MB / fds / threads" for k in range(n))
        + " | ticks/s | overruns | lost | worst gap (ms) | guard faults | recording MB |"
    )
    lines = [head, "|" + "---:|" * (head.count("|") - 1)]
    for s in samples:
        d = s["daemon"]
        renders = " | ".join(
            "ended" if r is None else f"{r['rss_mb']:.1f} / {r['fds']} / {r['threads']}"
            for r in s["renderers"]
        )
        lines.append(
            f"| {s['round'] + 1} | {s['t_s'] / 60:.1f} | {d['rss_mb']:.1f} | {d['fds']} | "
            f"{d['threads']} | {renders} | {s['tick_rate_hz']:.0f} | {s['overruns']} | "
            f"{s['lost_ticks']} | {s['worst_pose_gap_ms']:.1f} | {s['guard_faults']} | "
            f"{s['recording_mb']:.1f} |"
        )
    flat, v, f = data["flat"], data["verify"], data["findings"]
    ref = flat["reference_round"]
    rows = []
    for name, x in flat.items():
        if name == "reference_round":
            continue
        if x is None:
            end = next(e for e in data["renderers_ended"] if f"renderer {e['renderer']}" == name)
            log = f" (its whole log: `{end['log']}` in --out)" if end.get("log") else ""
            rows.append(f"{name}: ended before round {end['round']}: {end['why']}{log}")
            continue
        rows.append(
            f"{name}: resident memory in the last row {100 * (x['rss_ratio'] - 1):+.1f} % against "
            f"row {ref} (highest from row {ref} on {100 * (x['rss_max_ratio'] - 1):+.1f} %), "
            f"descriptors {x['fds']}, threads {x['threads']}"
        )
    return "\n".join(
        [
            f"{data['rounds']} rounds of {data['round_s']:g} s each: a daemon (simulated arm, "
            f"recording, a device fault every {FAULT_TICKS:,} ticks), two headless renderers "
            f"({RENDER_SIZE} at {RENDER_FPS} fps), {JOINS_PER_ROUND} subscribers joining and "
            "leaving and a control client (status, set, mark, a load of 1AON and of 1CRN by "
            "their bytes) each round; each sample is taken after the round's loads, once the "
            f"loop has run {SETTLE_TICKS} ticks on. The worst pose gap includes the injected "
            "stalls (40 ms) and slow reads. Load average at the end: "
            f"{data['load_average_1min']:.1f} on {os.cpu_count()} cores, shared with other "
            "work.",
            "",
            *lines,
            "",
            *[f"- {r}" for r in rows],
            f"- the recording: {v['ticks']:,} ticks, {data['summary']['bytes_total'] / 1e6:.0f} "
            f"MB; `replay --verify`: max force difference {v['max_force_diff_n']:g} N, "
            f"{v['flag_mismatches']} flag mismatches ({'OK' if v['ok'] else 'DIFFERENT'}) in "
            f"{v['wall_s']:.0f} s, peak {v['peak_rss_mb']:.0f} MB; `--findings`: "
            f"{f['wall_s']:.0f} s, peak {f['peak_rss_mb']:.0f} MB",
        ]
    )
