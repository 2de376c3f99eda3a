"""A hand pressing an emulated arm into the molecule through a real daemon: the poses until
one matches, the press once it has settled, and a bounded wait for any condition."""

from __future__ import annotations

import time

import numpy as np
from sasprobe.protocol.client import Subscriber
from sasprobe.protocol.pose import FLAG_CONTACT, FLAG_FAULT

from tests.support.daemon_process import DaemonProcess


def poses_until(sub: Subscriber, condition, daemon: DaemonProcess, timeout_s: float = 60.0):
    """Poll poses until `condition(pose)` holds for one; AssertionError after the timeout."""
    deadline = time.monotonic() + timeout_s
    seen = 0
    while time.monotonic() < deadline:
        for pose in sub.poll(0.1):
            seen += 1
            if condition(pose):
                return pose
    last = sub.pose
    raise AssertionError(
        f"no such pose among {seen} within {timeout_s} s; last flags "
        f"{last.flags if last else None}, force {last.force_N if last else None}; "
        f"daemon stderr: {daemon.stderr[-1500:]}"
    )


def pushing(pose) -> bool:
    return (
        pose.has(FLAG_CONTACT) and not pose.has(FLAG_FAULT) and np.linalg.norm(pose.force_N) > 0.05
    )


# The arms' emulators (the Falcon's USB and the serial boards) are Python threads in this
# test process: on a loaded test machine (other processes, or a hypervisor taking the
# CPUs) their replies are sometimes late for a 1 kHz loop, and each late reply is a fault
# that restarts the daemon's force ramp. With two busy processes beside it, the emulated
# Falcon's press saw 50-79 faulty ticks in 8 s at 1 kHz and none at 250 Hz, where a read
# may take 12 ms and a serial driver waits 10 ms for a reply. The presses compare forces,
# so they run at 250 Hz; 1 kHz timing is measured by `sasprobe bench daemon`.
EMULATED_ARM_RATE = ("--rate", "250")
# The whole molecule in the cube, so the workspace centre, where the hands press, is inside it
# (the default cube is a few residues on the surface).
WHOLE = ("--cube-half", "fit")


def wait_for(condition, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "condition not reached"
        time.sleep(0.01)


def poses_for(sub: Subscriber, seconds: float) -> list:
    poses, deadline = [], time.monotonic() + seconds
    while time.monotonic() < deadline:
        poses += sub.poll(0.05)
    return poses


def settled(
    sub: Subscriber, daemon: DaemonProcess, window_s: float = 0.5, timeout_s: float = 60.0
) -> list:
    """The poses of the first half second in which the written force holds steady (every pose
    pushing, the mean within 1 % of the previous window's): a loaded machine's subscriber
    may run behind, so a fixed wait can still land in the ramp, and its emulated boards
    answer late now and then (each late reply a fault that ramps the force in again over
    a second), so a steady press may take a while to come."""
    previous, deadline = None, time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        poses = poses_for(sub, window_s)
        if not poses or not all(pushing(p) for p in poses):
            previous = None
            continue
        force = np.linalg.norm(np.mean([p.force_N for p in poses], axis=0))
        if previous is not None and abs(force - previous) <= 0.01 * previous:
            return poses
        previous = force
    raise AssertionError(
        f"the press never settled within {timeout_s:g} s; daemon stderr: {daemon.stderr[-1500:]}"
    )
