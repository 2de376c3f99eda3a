"""The worst pose gap while a client loads a large structure (`sasprobe bench daemon`'s part).

A daemon (simulated arm, embedded 1CRN, its default real-time scheduling) publishes on
ipc://; this process subscribes and keeps, for every pair of consecutive poses, the gap
between their publish times (the daemon's own clock: when the loop ran, whatever this
process's scheduling). A sentinel thread per CPU here, pinned to it, at a real-time
priority where allowed, sleeps 0.5 ms at a time and notes that CPU's own pauses (a VM's
stolen time, the kernel's own work: they stall whatever runs there, the loop included).
Two windows of equal length: idle, then a client loading the largest reference structure
(6ZU5, 165k atoms) and 1CRN in turn by bytes. The longest gap and the longest part of a gap no
machine pause explains are reported for both.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import threading
import time
from pathlib import Path

from sasprobe.cli.children import DaemonChild

GAP_NS = 2_000_000


class _Watch:
    def __init__(self, pub: str) -> None:
        import zmq

        self.gaps: list[tuple[int, int]] = []
        self.pauses: list[tuple[int, int]] = []
        self.poses = 0
        self._stop = threading.Event()
        self._sock = zmq.Context.instance().socket(zmq.SUB)
        self._sock.rcvhwm = 1_000_000
        self._sock.setsockopt(zmq.SUBSCRIBE, b"pose")
        self._sock.connect(pub)
        self._threads = [threading.Thread(target=self._collect, daemon=True)] + [
            threading.Thread(target=self._sentinel, args=(cpu,), daemon=True)
            for cpu in sorted(os.sched_getaffinity(0))
        ]
        for t in self._threads:
            t.start()

    def _collect(self) -> None:
        from sasprobe.protocol.pose import decode_pose

        last = None
        while not self._stop.is_set():
            if not self._sock.poll(50):
                continue
            pose = decode_pose(self._sock.recv_multipart()[1])
            if (
                last is not None
                and pose.seq == last[0] + 1
                and pose.publish_t_ns - last[1] > GAP_NS
            ):
                self.gaps.append((last[1], pose.publish_t_ns))
            last = (pose.seq, pose.publish_t_ns)
            self.poses += 1

    def _sentinel(self, cpu: int) -> None:
        try:
            os.sched_setaffinity(0, {cpu})  # 0: the calling thread
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(60))
        except (OSError, AttributeError):
            pass
        last = time.monotonic_ns()
        while not self._stop.is_set():
            time.sleep(0.0005)
            now = time.monotonic_ns()
            if now - last > GAP_NS:
                self.pauses.append((last, now))
            last = now

    def window(self, start: int, end: int) -> dict:
        longest = rest = 1.0
        for a, b in self.gaps:
            if start <= b and a <= end:
                covered = sum(max(0, min(b, d) - max(a, c)) for c, d in self.pauses)
                longest, rest = max(longest, (b - a) / 1e6), max(rest, (b - a - covered) / 1e6)
        return {"longest_gap_ms": longest, "unexplained_ms": rest}

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join()
        self._sock.close(linger=0)


def loading_gap(big: Path, small_bytes: bytes, seconds: float) -> dict:
    """Idle and loading windows of `seconds` each against one daemon; figures for both."""
    from sasprobe.protocol.client import ControlClient

    folder = Path(tempfile.mkdtemp(prefix="spl"))
    child = DaemonChild(
        ["--device", "sim", "--pub", f"ipc://{folder}/p", "--ctl", f"ipc://{folder}/c"],
        folder / "daemon.log",
    )
    try:
        ready = child.wait_ready(90.0)
        watch = _Watch(f"ipc://{folder}/p")
        data, loads, atoms = big.read_bytes(), 0, None
        try:
            time.sleep(1.0)  # joined and warm
            t0 = time.monotonic_ns()
            time.sleep(seconds)
            t1 = time.monotonic_ns()
            with ControlClient(f"ipc://{folder}/c", timeout_s=120) as client:
                while time.monotonic_ns() - t1 < seconds * 1e9:
                    atoms = client.load(data=data, name=big.name)["structure"]["n_atoms"]
                    client.load(data=small_bytes, name="1crn")
                    loads += 1
                status = client.status()
            t2 = time.monotonic_ns()
        finally:
            watch.close()
        return {
            "realtime": bool(ready.get("realtime")),
            "seconds": seconds,
            "loads_of_big": loads,
            "atoms_of_big": atoms,
            "idle": watch.window(t0, t1),
            "loading": watch.window(t1, t2),
            "poses": watch.poses,
            "machine_pauses": len(watch.pauses),
            "daemon_stalls": status["loop"]["stalls"],
            "load_average_1min": os.getloadavg()[0],
        }
    finally:
        child.stop(30.0)
        shutil.rmtree(folder, ignore_errors=True)


def markdown(r: dict, name: str) -> str:
    idle, loading = r["idle"], r["loading"]
    return (
        f"\n\nWorst pose gap while a client loads {name} ({r['atoms_of_big']} atoms) and 1CRN in "
        f"turn by bytes ({r['loads_of_big']} loads in {r['seconds']:g} s), against the same "
        f"daemon idle for as long (scheduling {'FIFO' if r['realtime'] else 'normal'}; "
        "consecutive poses' publish times; a machine pause is a late wake-up of a real-time "
        f"sentinel thread, {r['machine_pauses']} seen; load avg "
        f"{r['load_average_1min']:.1f}):\n\n| window | longest pose gap (ms) | longest not "
        "explained by a machine pause (ms) |\n|---|---:|---:|\n| idle | "
        f"{idle['longest_gap_ms']:.1f} | {idle['unexplained_ms']:.1f} |\n| loading | "
        f"{loading['longest_gap_ms']:.1f} | {loading['unexplained_ms']:.1f} |\n"
    )
