"""`sasprobe bench rates`: the loop at 1, 2 and 4 kHz on the arms that run it, on a quiet
machine and beside busy loops.

Each row starts `sasprobe daemon --device ... --rate R` (no subscriber, no recording: the
loop alone) on the simulated arm or on a device-side stand-in from the checkout's
`tests/emulators/` (the DHD library, fake_libdhd.c, loaded into the daemon; the Inverse
Service, a WebSocket server in this process), and after a warm-up reads the loop's
figures from `status`. The stand-ins' own threads run at a real-time priority below the
loop's (STAND_IN_PRIORITY), as the DHD stand-in's physics thread does by living in the
daemon: a stand-in written in Python needs far more CPU per message than the device or
service it stands in for, and starved by the busy loops it would measure itself, not the
daemon. The CPU it takes then counts against the kernel's real-time budget, which a 4 kHz
Inverse3 row can exhaust. "Busy" rows run with `--busy N` processes beside it that spin
for as long as the rows last (at normal priority, as another user's jobs would); the
machine's own load is reported beside each row, since "quiet" is only as quiet as the
machine is. The benchmark runs by name only, never in `sasprobe bench`'s full run: it
wants a machine chosen for it, and `--page` writes its own part of the benchmark page.
"""

from __future__ import annotations

import os
import subprocess
import sys

from sasprobe.cli.bench import BenchContext, BenchResult, daemon_devices
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress

TITLE = "Loop rates: period error, overruns, failed reads, tick work and CPU, quiet and busy"
RATES_HZ = (1000, 2000, 4000)
DEVICES: dict[str, tuple[str, dict] | None] = {  # as daemon_devices.DEVICES
    "simulated arm": None,
    "Force Dimension omega.3 (stand-in libdhd)": ("libdhd", {}),
    "Haply Inverse3 (stand-in Inverse Service)": ("inverse_service", {}),
}
BUSY_LOOPS = 2
STAND_IN_PRIORITY = 40  # SCHED_FIFO of the stand-ins' threads started here (the loop's: 50)
TARGETS = (
    "every arm at 1 kHz with ≤ 0.1 % failed reads beside two busy loops; the simulated arm "
    "and the stand-in DHD at 4 kHz with p99 period error ≤ 50 µs quiet and ≤ 0.1 % late "
    "ticks busy"
)


def add_arguments(parser) -> None:
    from sasprobe.cli.argtypes import positive_float

    parser.add_argument(
        "--seconds",
        type=positive_float,
        default=None,
        help="measured window per row (default 10, --quick 3)",
    )
    parser.add_argument(
        "--busy",
        type=int,
        default=BUSY_LOOPS,
        metavar="N",
        help=f"spinning processes beside the busy rows (default {BUSY_LOOPS}; 0: quiet rows only)",
    )
    parser.add_argument(
        "--rates",
        default=",".join(str(r) for r in RATES_HZ),
        metavar="HZ,...",
        help="loop rates (default 1000,2000,4000)",
    )


class BusyLoops:
    """N processes that spin at normal priority until closed."""

    def __init__(self, n: int) -> None:
        self.procs = [
            subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)
        ]

    def close(self) -> None:
        for p in self.procs:
            p.kill()
        for p in self.procs:
            p.wait()


def realtime_processes() -> int:
    """User processes now running under a real-time policy (SCHED_FIFO or SCHED_RR): other
    haptic loops, which take the CPU from this one whatever the load average says."""
    count = 0
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        # fields[0] is the state (stat field 3): ppid 2 is a kernel thread; policy is field 41
        if fields[1] != "2" and entry.name != "2" and int(fields[38]) in (1, 2):
            count += 1
    return count


def start_stand_in(module: str, options: dict):
    """A stand-in whose threads (started here, they inherit it) run at SCHED_FIFO
    STAND_IN_PRIORITY; where that is refused, at normal priority."""
    from sasprobe.daemon.realtime import current_scheduling, restore_scheduling

    saved = current_scheduling()
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(STAND_IN_PRIORITY))
    except OSError:
        pass
    try:
        return daemon_devices.launch(module, options)
    finally:
        restore_scheduling(saved)


def _rates(text: str) -> list[float]:
    try:
        rates = [float(r) for r in text.split(",") if r.strip()]
    except ValueError:
        raise UserError(f"--rates {text}: expected rates in Hz, comma-separated") from None
    if not rates or any(r <= 0 for r in rates):
        raise UserError(f"--rates {text}: expected positive rates")
    return rates


def measure(
    seconds: float, rates_hz, busy: int, devices: dict | None = None, warmup_s: float = 1.0
) -> dict:
    """One row per load (quiet, then busy when `busy` > 0), device and rate."""
    if not daemon_devices.emulators_available():
        raise UserError("needs the repository's tests/emulators/ (run from a checkout)")
    devices = DEVICES if devices is None else devices
    loads = ["quiet"] + (["busy"] if busy > 0 else [])
    runs = [(load, label, rate) for load in loads for label in devices for rate in rates_hz]
    rows, loops, current = [], None, None
    try:
        for load, label, rate in progress(runs, desc="bench rates", total=len(runs)):
            if load != current:
                current = load
                loops = BusyLoops(busy) if load == "busy" else None
            try:
                result = daemon_devices.measure_one(
                    devices[label],
                    warmup_s,
                    seconds,
                    rate_hz=rate,
                    record=False,
                    starter=start_stand_in,
                )
            except Exception as exc:  # a stand-in that cannot start (no C compiler) skips its row
                rows.append(
                    {"load": load, "label": label, "rate_hz": rate, "error": str(exc)[:200]}
                )
                continue
            rows.append(
                {
                    "load": load,
                    "label": label,
                    "rate_hz": rate,
                    "load_average_1min": os.getloadavg()[0],
                    "other_realtime": realtime_processes(),
                    **result,
                }
            )
    finally:
        if loops is not None:
            loops.close()
    return {"seconds": seconds, "busy_loops": busy, "rows": rows}


def late_percent(loop: dict) -> float:
    """Deadlines the loop missed (ticks that started a period or more late skip them), as a
    share of the deadlines in the window."""
    due = loop["ticks"] + loop["missed_deadlines"]
    return 100.0 * loop["missed_deadlines"] / due if due else 0.0


def run(ctx: BenchContext, args=None) -> BenchResult:
    seconds = getattr(args, "seconds", None) or (0.5 if ctx.smoke else 3.0 if ctx.quick else 10.0)
    rates = _rates(getattr(args, "rates", None) or ",".join(map(str, RATES_HZ)))
    busy = getattr(args, "busy", BUSY_LOOPS)
    devices = DEVICES
    if ctx.smoke:
        rates, busy, devices = rates[-1:], 0, dict(list(DEVICES.items())[:1])
    data = measure(seconds, rates, busy, devices)
    data["targets"] = TARGETS
    return BenchResult("rates", data, markdown(data))


def _f(v, digits: int = 0) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def markdown(data: dict) -> str:
    lines = [
        "| busy loops | device | rate (Hz) | period error p50 / p99 / max (µs) "
        "| overruns (late ticks) | failed reads | tick work p50 / p99 / max (µs) | loop CPU "
        "| load avg | other real-time |",
        "|---|---|---:|---|---|---:|---|---:|---:|---:|",
    ]
    for r in data["rows"]:
        where = 0 if r["load"] == "quiet" else data["busy_loops"]
        if "error" in r:
            lines.append(
                f"| {where} | {r['label']} | {r['rate_hz']:g} | not run: {r['error']} |||||"
            )
            continue
        loop, err, work = r["loop"], r["loop"]["period_error_us"], r["loop"]["work_us"]
        failed = loop["failed_reads"]
        lines.append(
            f"| {where} | {r['label']} | {loop['rate_hz']:.0f} of {r['rate_hz']:g} | "
            f"{_f(err['p50'])} / {_f(err['p99'])} / {_f(err['max'])} | "
            f"{loop['overruns']} ({late_percent(loop):.2f} %) | "
            f"{failed} ({100.0 * failed / max(loop['ticks'], 1):.2f} %) | "
            f"{_f(work['recent_p50'])} / {_f(work['recent_p99'])} / {_f(work['max'])} | "
            f"{_f(loop['cpu_percent'])} % | {r['load_average_1min']:.1f} | {r['other_realtime']} |"
        )
    return (
        f"Each row: `sasprobe daemon --device ... --rate R` for {data['seconds']:g} s after a "
        "1 s warm-up, no subscriber and no recording, on the simulated arm or on a device-side "
        "stand-in from `tests/emulators/` (the DHD library loaded into the daemon; the Inverse "
        "Service in the benchmark's process, its threads at SCHED_FIFO "
        f"{STAND_IN_PRIORITY}, below the loop's), beside no or "
        f"{data['busy_loops']} processes of the benchmark's that spin at normal priority (busy "
        "loops; the machine's own load is in the last column). Period error is |interval "
        "between tick starts − period| (1 µs bins); an overrun is a tick that started a full "
        "period late, and late ticks are the deadlines such ticks skipped, as a share of all "
        "deadlines; a failed read is a tick whose read raised or took over 3 periods (zero "
        "force); tick work runs from a tick's start to the end of its work (the last ~1000 "
        "ticks); loop CPU is the loop thread's CPU time over wall time; load avg is the "
        f"machine's 1-minute load average at the end of the row ({os.cpu_count()} cores), and "
        "other real-time the processes of other users then running under a real-time policy "
        "(other haptic loops, which compete with this one whatever the load average says). "
        f"Targets: {TARGETS}.\n\n" + "\n".join(lines)
    )
