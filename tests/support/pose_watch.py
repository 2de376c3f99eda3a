"""A process that watches a daemon's pose stream and the machine itself, for the probe tests.

`python -m tests.support.pose_watch PUB_ENDPOINT` subscribes to the poses with a plain ZeroMQ
socket (no sasprobe client: `seq` and `publish_t_ns` are read at the byte offsets of
protocol/README.md), checks each pose against protocol/schemas/pose.json with
tests/support/schema_check.py (its README-table decoder), and, in a real-time thread per CPU
(pinned to it) where the system allows one, sleeps 0.5 ms at a time and notes every
wake-up that came late: a pause of that CPU that no process chose (a VM's stolen time,
the kernel's own work such as the loopback traffic of a 256 MiB request), which stalls
the daemon too when its loop runs there, without being its fault. It prints "ready" once
poses arrive and, when its stdin closes, one JSON line: the poses received,
the first few that broke the protocol (`invalid`, with why), the pose gaps and the machine
pauses over 2 ms, as [start_ns, end_ns] on the monotonic clock, which the daemon shares.
"""

from __future__ import annotations

import json
import os
import struct
import sys
import threading
import time

import zmq

from tests.support.schema_check import check_pose_payload

GAP_NS = 2_000_000
SEQ = struct.Struct("<Q")  # offset 8
PUBLISH_T = struct.Struct("<q")  # offset 24


def _sentinel(cpu: int, pauses: list, stop: threading.Event) -> None:
    try:
        os.sched_setaffinity(0, {cpu})  # 0: the calling thread
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(60))
    except (OSError, AttributeError):
        pass
    last = time.monotonic_ns()
    while not stop.is_set():
        time.sleep(0.0005)
        now = time.monotonic_ns()
        if now - last > GAP_NS:
            pauses.append((last, now))
        last = now


def main(endpoint: str) -> None:
    sock = zmq.Context.instance().socket(zmq.SUB)
    sock.rcvhwm = 1_000_000
    sock.setsockopt(zmq.SUBSCRIBE, b"pose")
    sock.connect(endpoint)
    pauses: list = []
    gaps: list = []
    stop = threading.Event()
    for cpu in sorted(os.sched_getaffinity(0)):
        threading.Thread(target=_sentinel, args=(cpu, pauses, stop), daemon=True).start()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    last = None
    poses = invalid = 0
    why: list = []
    while not stop.is_set():
        if not sock.poll(50):
            continue
        while True:
            try:
                payload = sock.recv_multipart(zmq.NOBLOCK)[1]
            except zmq.Again:
                break
            try:
                check_pose_payload(payload)
            except AssertionError as exc:
                invalid += 1
                if len(why) < 5:
                    why.append(str(exc)[:300])
                if len(payload) < 32:
                    continue
            seq, t = SEQ.unpack_from(payload, 8)[0], PUBLISH_T.unpack_from(payload, 24)[0]
            if last is not None and seq == last[0] + 1 and t - last[1] > GAP_NS:
                gaps.append((last[1], t))
            last = (seq, t)
            poses += 1
            if poses == 1:
                print("ready", flush=True)
    print(
        json.dumps(
            {"poses": poses, "invalid": invalid, "why": why, "gaps": gaps, "pauses": pauses}
        ),
        flush=True,
    )


if __name__ == "__main__":
    main(sys.argv[1])
