"""What `sasprobe demo` measures and reports: every pose the daemon publishes, as a
renderer receives them (ForceMonitor), summary.json (demo_summary) and the closing lines
(print_summary)."""

from __future__ import annotations

from array import array
from pathlib import Path

import numpy as np

from sasprobe import __version__
from sasprobe.cli.bench.machine import steal_between

# below it, steal costs no more deadlines than the loop misses on its own
STEAL_WORTH_TELLING_PERCENT = 1.0


class ForceMonitor:
    """Every pose the daemon publishes (as a renderer sees them): force magnitudes against
    the device's continuous rating, contacts, touched atoms and when the first one was
    touched (device time from the first pose seen). Polled without blocking from the
    demo's main loop."""

    def __init__(
        self,
        endpoint: str,
        continuous_force_n: float | None = None,
        rate_hz: float | None = None,
        keys=None,
    ) -> None:
        from sasprobe.protocol.client import Subscriber

        self.subscriber = Subscriber(endpoint, keys=keys)
        self.continuous_force_n = continuous_force_n
        self.rate_hz = rate_hz
        self.force_n = array("f")
        self.contact_ticks = 0
        self.clamped_ticks = 0
        self.fault_ticks = 0
        self.above_continuous_ticks = 0
        self.touched: set[int] = set()
        self._first_t_ns: int | None = None
        self.first_touch_s: float | None = None

    def poll(self) -> None:
        from sasprobe.protocol.pose import FLAG_CLAMPED, FLAG_CONTACT, FLAG_FAULT

        for pose in self.subscriber.poll():
            force = float(np.linalg.norm(pose.force_N))
            self.force_n.append(force)
            self.contact_ticks += bool(pose.flags & FLAG_CONTACT)
            self.clamped_ticks += bool(pose.flags & FLAG_CLAMPED)
            self.fault_ticks += bool(pose.flags & FLAG_FAULT)
            if self.continuous_force_n is not None and force > self.continuous_force_n:
                self.above_continuous_ticks += 1
            if self._first_t_ns is None:
                self._first_t_ns = pose.device_t_ns
            if pose.touched_atom >= 0:
                self.touched.add(pose.touched_atom)
                if self.first_touch_s is None:
                    self.first_touch_s = (pose.device_t_ns - self._first_t_ns) / 1e9

    def last_force(self) -> float | None:
        return float(self.force_n[-1]) if self.force_n else None

    def contact_fraction(self) -> float | None:
        return self.contact_ticks / len(self.force_n) if self.force_n else None

    def summary(self) -> dict:
        f = (
            np.frombuffer(self.force_n, dtype=np.float32).astype(np.float64)
            if self.force_n
            else np.zeros(0)
        )

        def stats(fn):
            return float(fn(f)) if f.size else None

        return {
            "poses": int(f.size),
            "poses_missed": self.subscriber.missed,
            "force_n": {
                "mean": stats(np.mean),
                "median": stats(np.median),
                "p95": stats(lambda a: np.percentile(a, 95)),
                "max": stats(np.max),
            },
            "contact_ticks": self.contact_ticks,
            "contact_fraction": self.contact_fraction(),
            "atoms_touched": len(self.touched),
            "clamped_ticks": self.clamped_ticks,
            "fault_ticks": self.fault_ticks,
            "continuous_force_n": self.continuous_force_n,
            "above_continuous_ticks": self.above_continuous_ticks,
            "above_continuous_s": self.above_continuous_ticks / self.rate_hz
            if self.rate_hz
            else None,
            "first_touch_s": self.first_touch_s,
        }

    def close(self) -> None:
        self.subscriber.close()


def demo_summary(session, headless: bool, seconds: float | None, interrupted: bool) -> dict:
    """summary.json: the daemon's loop over the measured window, the forces the demo saw,
    the renderer's report, how each child ended and the files written."""
    end = session.status_end or session.last_status or {}
    loop = end.get("loop") or {}
    nominal = loop.get("target_rate_hz")
    rate = loop.get("rate_hz")
    haptics = None
    if loop:
        haptics = {
            "nominal_rate_hz": nominal,
            "rate_hz": rate,
            "rate_error_percent": 100.0 * (rate - nominal) / nominal if rate and nominal else None,
            "window_s": loop["window_s"],
            "ticks": loop["ticks"],
            "period_error_us": loop["period_error_us"],
            "overruns": loop["overruns"],
            "missed_deadlines": loop["missed_deadlines"],
            "tick_work_us": loop["work_us"],
            "loop_cpu_percent": loop.get("cpu_percent"),
            "realtime": bool(session.ready.get("realtime")),
            "cpu_steal": steal_between(session.steal_from, session.steal_to),
            "device_faults": end["device"]["faults"],
        }
    files = {}
    if headless:
        files = {
            "video": str(session.video) if session.video.exists() else None,
            "snapshot": str(session.snapshot) if session.snapshot.exists() else None,
        }
    if session.opts.record:
        files["recording"] = str(session.opts.record)
    return {
        "sasprobe_version": __version__,
        "mode": "headless" if headless else "window",
        "seconds": seconds,
        "interrupted": interrupted,
        "device": session.opts.device,
        "structure": end.get("structure"),
        "haptics": haptics,
        "forces": session.monitor.summary() if session.monitor is not None else None,
        "renderer": session.renderer_report(),
        "renderer_exit_status": session.renderer_rc,
        "daemon_exit": session.exit_report,
        "daemon_exit_status": session.daemon_rc,
        "files": files,
        "notes": session.notes,
    }


def print_summary(summary: dict, path: Path) -> None:
    """The summary in a few lines on stdout (summary.json holds all of it)."""
    s = summary
    structure = s["structure"] or {}
    print(
        f"sasprobe demo: {structure.get('name', '?')} ({structure.get('n_atoms', '?')} atoms), "
        f"device {s['device']}, "
        f"{s['mode']}" + (" (interrupted)" if s["interrupted"] else "")
    )
    h = s["haptics"]
    if h:
        print(
            f"  haptics   {h['rate_hz']:.1f} Hz (nominal {h['nominal_rate_hz']:g}) over "
            f"{h['window_s']:.1f} s, period error p99 {h['period_error_us']['p99']:.0f} µs, "
            f"{h['overruns']} overruns, {'real-time' if h['realtime'] else 'normal'} scheduling"
        )
        stolen = h.get("cpu_steal")
        if stolen is not None and stolen["percent"] >= STEAL_WORTH_TELLING_PERCENT:
            print(
                f"            the hypervisor took {stolen['percent']:.1f} % of the CPUs' time "
                "(steal): deadlines lost to it are the virtual machine's, not the loop's"
            )
    f = s["forces"]
    if f and f["poses"]:
        print(
            f"  forces    mean {f['force_n']['mean']:.2f} N, p95 {f['force_n']['p95']:.2f} N, max "
            f"{f['force_n']['max']:.2f} N; in contact {100 * f['contact_fraction']:.0f} % of "
            f"ticks, {f['atoms_touched']} atoms touched"
            + (
                f" (the first after {f['first_touch_s']:.1f} s)"
                if f["first_touch_s"] is not None
                else ""
            )
        )
        if f["continuous_force_n"] is not None:
            above = f["above_continuous_s"]
            print(
                f"            {f['clamped_ticks']} ticks clamped to the peak rating; above the "
                f"continuous rating ({f['continuous_force_n']:g} N) for "
                + (
                    f"{above:.2f} s"
                    if above is not None
                    else f"{f['above_continuous_ticks']} ticks"
                )
            )
    r = s["renderer"]
    if r:
        lost = (r.get("daemon") or {}).get("poses_missed")
        print(
            f"  renderer  {r['frames']} frames at {r['fps'] or 0:.1f} fps "
            f"({r['size'][0]}x{r['size'][1]})"
            + (f", {r['video_frames']} video frames" if r.get("video_frames") else "")
            + (f", {lost} poses lost" if lost is not None else "")
            + (
                f"; molecule layer kept in {r['molecule_layer']['kept']} of {r['frames']} frames"
                if r.get("molecule_layer")
                else ""
            )
        )
    d = s["daemon_exit"]
    if d:
        print(
            f"  stopped   daemon: {d['reason']}, last force written {d['last_force_written_n']} N"
        )
    for note in s["notes"]:
        print(f"  note      {note}")
    written = [p for p in s["files"].values() if p] + [str(path)]
    print("  wrote     " + ", ".join(written))
