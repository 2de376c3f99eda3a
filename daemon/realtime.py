"""Real-time scheduling: the loop's SCHED_FIFO priority, the helper threads' below it and
the watchdog's above it, and giving the thread its scheduling back when the daemon stops."""

from __future__ import annotations

import logging
import os

log = logging.getLogger("sasprobe")

REALTIME_PRIORITY = 50  # SCHED_FIFO priority of the loop (1-99), asked for unless --no-realtime
WATCHDOG_ABOVE_LOOP = 1  # the stall watchdog's priority steps above the loop's
REALTIME_FIX = (
    "allow real-time scheduling: run as root, grant CAP_SYS_NICE (`sudo setcap cap_sys_nice+ep "
    "$(readlink -f $(which python3))`), or give your user an rtprio limit "
    "(`@USER - rtprio 60` in /etc/security/limits.conf, then log in again)"
)


def enter_realtime(priority: int = REALTIME_PRIORITY) -> bool:
    """SCHED_FIFO for the calling thread (and the threads it starts); False, with one line
    saying what that costs and how to allow it, when not permitted.

    Without root or CAP_SYS_NICE an rtprio resource limit still allows SCHED_FIFO up to
    its value, so the priority asked for is capped there (the soft limit raised to the
    hard one first)."""
    import resource

    try:
        if os.geteuid() != 0:
            soft, hard = resource.getrlimit(resource.RLIMIT_RTPRIO)
            if soft < hard:
                resource.setrlimit(resource.RLIMIT_RTPRIO, (hard, hard))
                soft = hard
            if 0 < soft < priority:
                priority = int(soft)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return True
    except (OSError, AttributeError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        log.warning(
            "real-time scheduling refused (%s): the haptic loop competes with every other "
            "process and loses ticks (zero force) whenever the CPU is busy; to allow it, %s; "
            "--no-realtime says you know",
            reason,
            REALTIME_FIX,
        )
        return False


def current_scheduling() -> tuple[int, int]:
    """(policy, priority) of the calling thread, for `restore_scheduling`."""
    return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority


def restore_scheduling(saved: tuple[int, int]) -> None:
    """Give the calling thread back the scheduling it had before `enter_realtime`: a daemon
    run inside another program (a test, a notebook) must not leave it, and every process it
    starts afterwards, at the loop's real-time priority."""
    try:
        os.sched_setscheduler(0, saved[0], os.sched_param(saved[1]))
    except OSError as exc:
        log.warning("could not restore the thread's scheduling after the loop: %s", exc)


def helper_priority() -> None:
    """Helper threads (control, recorder) drop to the lowest real-time priority: still ahead
    of ordinary processes, since a helper preempted while it holds the GIL would stall the
    loop until it runs again, but behind the loop."""
    try:
        if os.sched_getscheduler(0) == os.SCHED_FIFO:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except (OSError, AttributeError):
        pass


def above_loop_priority() -> None:
    """The calling thread (the stall watchdog) one real-time priority step above the loop's,
    when the loop runs under SCHED_FIFO."""
    try:
        if os.sched_getscheduler(0) == os.SCHED_FIFO:
            priority = os.sched_getparam(0).sched_priority + WATCHDOG_ABOVE_LOOP
            os.sched_setscheduler(
                0,
                os.SCHED_FIFO,
                os.sched_param(min(priority, os.sched_get_priority_max(os.SCHED_FIFO))),
            )
    except (OSError, AttributeError):
        pass
