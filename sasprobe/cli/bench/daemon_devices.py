"""The daemon's loop on every emulated device: does any driver's read hold the tick?

Each row starts one device-side emulator from the checkout's `tests/emulators/` (written
from the makers' public firmware and host code, importing nothing from sasprobe) in this
process, then `sasprobe daemon --device ...` on it as a subprocess (at the rate the device
declares, or at each rate of `--device-rate`), and reads the loop's figures from `status`
after a warm-up. The simulated arm runs in the same run as the
baseline, so each driver's cost is a difference and an overrun ratio measured side by
side. Without a checkout (an installed wheel has no tests/) the rows are skipped.
"""

from __future__ import annotations

import importlib
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

from sasprobe.cli.children import DaemonChild
from sasprobe.cli.reference_data import REPO_ROOT
from sasprobe.common.progress import progress

READY_S = 90.0
STOP_S = 30.0

# row label -> (emulator module under tests.emulators, launch options); None: the simulated arm
DEVICES: dict[str, tuple[str, dict] | None] = {
    "simulated arm (baseline)": None,
    "Novint Falcon": ("falcon_usb", {}),
    "WoodenHaptics Woody": ("woodenhaptics_serial", {"model": 3}),
    "WoodenHaptics Polhem": ("woodenhaptics_serial", {"model": 1}),
    "Haply 2DIY gen 3": ("haply_serial", {"generation": "gen3"}),
    "SpaceMouse Compact": ("spacemouse_hid", {}),
    "OpenHaptics (stand-in libHD)": ("libhd", {"inkwell": True}),
    "Force Dimension omega.3 (stand-in libdhd)": ("libdhd", {}),
    "Haply Inverse3 (stand-in Inverse Service)": ("inverse_service", {}),
}


def emulators_available() -> bool:
    return (REPO_ROOT / "tests" / "emulators" / "__init__.py").is_file()


def launch(module: str, options: dict):
    if str(REPO_ROOT) not in sys.path:
        sys.path.insert(0, str(REPO_ROOT))
    return importlib.import_module(f"tests.emulators.{module}").launch(**options)


def measure_one(
    spec: tuple[str, dict] | None,
    warmup_s: float,
    seconds: float,
    rate_hz: float | None = None,
    record: bool = True,
    starter=None,
) -> dict:
    """One daemon on one device (`spec`: an emulator module and its options; None: the
    simulated arm) for `seconds` after `warmup_s`: its loop's figures from `status`, and with
    `record` the read times and failures from its recording of the same window. `starter`
    starts the emulator (default `launch`)."""
    from sasprobe.protocol.client import ControlClient

    emulator = None if spec is None else (starter or launch)(*spec)
    folder = Path(tempfile.mkdtemp(prefix="spbd"))
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(filter(None, [str(REPO_ROOT), os.environ.get("PYTHONPATH")])),
    )
    device = "sim"
    if emulator is not None:
        env.update(emulator.env)
        device = emulator.device_spec
    ctl = f"ipc://{folder}/ctl"
    recording = folder / "reads.mcap"
    rate = ["--rate", f"{rate_hz:g}"] if rate_hz else []
    child = DaemonChild(
        [
            "--device",
            device,
            *rate,
            "--pub",
            f"ipc://{folder}/pub",
            "--ctl",
            ctl,
            *(["--record", str(recording)] if record else []),
        ],
        folder / "daemon.log",
        env=env,
        cwd=folder,
    )
    try:
        child.wait_ready(READY_S)
        with ControlClient(ctl, timeout_s=10) as client:
            time.sleep(warmup_s)
            client.status(reset_stats=True)
            window = (time.monotonic_ns(), None)
            time.sleep(seconds)
            status = client.status()
            window = (window[0], time.monotonic_ns())
        child.stop(STOP_S)
        result = {"device": status["device"]["model"], "loop": status["loop"]}
        if record:
            result["reads"] = _reads(recording, *window)
        return result
    finally:
        child.stop(STOP_S)
        if emulator is not None:
            emulator.close()
        shutil.rmtree(folder, ignore_errors=True)


def _reads(recording: Path, start_ns: int, end_ns: int) -> dict:
    """How long the device's read() took, and how many failed, over the measured window: the
    daemon records each tick's read time (`read_ns`) and error."""
    import numpy as np

    from sasprobe.protocol.recording import Recording
    from sasprobe.protocol.ticks import HAS_ERROR, TickBlock

    read_ns, failed = [], 0
    for item in Recording(recording).stream():
        if isinstance(item, TickBlock):
            log = item.log_ns
            inside = (log >= start_ns) & (log <= end_ns)
            read_ns.append(item.device["read_ns"][inside])
            failed += int(np.count_nonzero(item.device["device_flags"][inside] & HAS_ERROR))
    read_us = np.concatenate(read_ns).astype(float) / 1000.0 if read_ns else np.zeros(0)
    if not read_us.size:
        return {"ticks": 0}
    return {
        "ticks": int(read_us.size),
        "failed": failed,
        "p50_us": float(np.percentile(read_us, 50)),
        "p99_us": float(np.percentile(read_us, 99)),
        "max_us": float(read_us.max()),
    }


def measure(
    seconds: float,
    smoke: bool = False,
    rates_hz: list[float] | None = None,
    labels: list[str] | None = None,
) -> dict:
    """One row per emulated device and rate (or why there are none); `smoke`: one emulated
    device (the simulated arm runs in the rows before); `rates_hz`: the loop rates to run
    each at (None: the rate each device declares); `labels`: only these rows."""
    if not emulators_available():
        return {"skipped": "needs the repository's tests/emulators/ (run from a checkout)"}
    rows = []
    devices = list(DEVICES.items())[1:2] if smoke else list(DEVICES.items())
    if labels is not None:
        devices = [(label, DEVICES[label]) for label in labels]
    runs = [(label, spec, rate) for label, spec in devices for rate in (rates_hz or [None])]
    for label, spec, rate in progress(runs, desc="bench daemon: devices", total=len(runs)):
        try:
            result = measure_one(spec, warmup_s=1.0, seconds=seconds, rate_hz=rate)
        except (
            Exception
        ) as exc:  # one emulator that cannot start (no C compiler for libHD) skips its row
            rows.append({"label": label, "error": str(exc).splitlines()[0][:200]})
            continue
        rows.append({"label": label, "load_average_1min": os.getloadavg()[0], **result})
    return {"seconds": seconds, "rows": rows}


def markdown(data: dict) -> str:
    if "skipped" in data:
        return f"Emulated devices: skipped ({data['skipped']})."
    lines = [
        "| device | rate (Hz) | period error p99 / max (µs) | overruns "
        "| read p50 / p99 / max (µs) | failed reads | tick work p50 / "
        "p99 / max (µs) | work vs simulated arm (p50) | load avg |",
        "|---|---:|---|---:|---|---:|---|---:|---:|",
    ]
    base = next(
        (r for r in data["rows"] if r["label"].startswith("simulated") and "loop" in r), None
    )
    for r in data["rows"]:
        if "error" in r:
            lines.append(f"| {r['label']} | not run: {r['error']} | | | | | | | |")
            continue
        loop, err, work = r["loop"], r["loop"]["period_error_us"], r["loop"]["work_us"]
        ratio = (
            work["recent_p50"] / base["loop"]["work_us"]["recent_p50"]
            if base and work["recent_p50"] and base["loop"]["work_us"]["recent_p50"]
            else None
        )
        reads = r.get("reads", {})
        lines.append(
            f"| {r['label']} | {loop['rate_hz']:.1f} | {_f(err['p99'])} / {_f(err['max'])} | "
            f"{loop['overruns']} | {_f(reads.get('p50_us'))} / {_f(reads.get('p99_us'))} / "
            f"{_f(reads.get('max_us'))} | {reads.get('failed', '-')} of {reads.get('ticks', 0)} | "
            f"{_f(work['recent_p50'])} / {_f(work['recent_p99'])} / {_f(work['max'])} | "
            f"{'-' if ratio is None else f'{ratio:.2f}×'} | {r['load_average_1min']:.1f} |"
        )
    return (
        "Emulated devices: `sasprobe daemon --device ...` at the rate each device declares (or "
        f"as `--device-rate` says) for {data['seconds']:g} s (after a 1 s warm-up) on each "
        "device-side emulator of `tests/emulators/`, the emulator running in the benchmark "
        "process as the hardware would beside the host; tick work is read + haptics + write + "
        "publish; read times and failed reads come from the daemon's recording of the same "
        "window. A driver whose read waited on its link "
        "would show as overruns and a read p99 near its period.\n\n" + "\n".join(lines)
    )


def _f(v) -> str:
    return "-" if v is None else f"{v:.0f}"
