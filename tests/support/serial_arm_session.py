"""A host loop for the serial-arm tests: the daemon's tick in miniature, tolerant of late replies.

On a loaded test machine a reply sometimes misses the driver's 3 ms deadline; the
driver then raises DeviceFault for that tick (as it must) and the loop carries on, as
the daemon does. The helpers count those faults instead of failing on them.
"""

from __future__ import annotations

import time

import numpy as np
from sasprobe.devices.base import DeviceFault


class Session:
    def __init__(self, device, period_s: float = 0.001):
        self.device = device
        self.period_s = period_s
        self.faults = 0
        self.last_fault = ""
        self.state = None

    def tick(self, force=(0.0, 0.0, 0.0)):
        """read → write_force; the state read, or None when the read faulted."""
        try:
            self.state = state = self.device.read()
        except DeviceFault as exc:
            self.faults += 1
            self.last_fault = str(exc)
            state = None
        self.device.write_force(force(state) if callable(force) else force)
        time.sleep(self.period_s)
        return state

    def run(self, seconds: float, force=(0.0, 0.0, 0.0)) -> list:
        states, end = [], time.monotonic() + seconds
        while time.monotonic() < end:
            state = self.tick(force)
            if state is not None:
                states.append(state)
        return states

    def hold(
        self, force, board, seconds: float = 0.02, replies: int = 2, timeout_s: float = 2.0
    ) -> None:
        """Render `force` for `seconds` and until the board has answered `replies` more
        commands: a command already in flight when the force changed still carries the old
        one, so the second reply is the first that surely took the new force (on a loaded
        machine 20 ms may pass without one)."""
        start, begun = board.replies_sent, time.monotonic()
        try:
            self.until(
                lambda _s: (
                    board.replies_sent >= start + replies and time.monotonic() - begun >= seconds
                ),
                timeout_s,
                force,
            )
        except AssertionError as exc:  # what the board's own record says of those seconds
            raise AssertionError(
                f"{exc}; the board sent {board.replies_sent - start} replies meanwhile, its port "
                f"went unread for at most {board.longest_deaf_s * 1000:.0f} ms, its firmware "
                f"thread {'runs' if board.running else 'has ended'}"
            ) from None

    def until(self, condition, timeout_s: float = 10.0, force=(0.0, 0.0, 0.0)):
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            state = self.tick(force)
            if state is not None and condition(state):
                return state
        raise AssertionError(
            f"condition not reached in {timeout_s} s (faults {self.faults}: {self.last_fault})"
        )

    def reads_the_stylus(self, stylus, atol_mm: float = 0.5, force=(0.0, 0.0, 0.0)):
        """The next good read, asserted to be where the emulated stylus is (within `atol_mm`)."""
        state = self.until(lambda _s: True, force=force)
        np.testing.assert_allclose(state.position_mm, stylus.now(), atol=atol_mm)
        return state

    def settle(
        self, stylus, hand, timeout_s: float = 10.0, force=(0.0, 0.0, 0.0), rest_s: float = 0.03
    ):
        """Run until the hand has arrived and the stylus has rested for `rest_s`; the state read
        then."""
        since = [None]

        def resting(_state) -> bool:
            still = (
                np.allclose(hand.position, hand.target, atol=1e-9)
                and float(np.linalg.norm(stylus.velocity)) < 0.5
            )
            since[0] = (since[0] or time.monotonic()) if still else None
            return still and time.monotonic() - since[0] >= rest_s

        return self.until(resting, timeout_s, force)


def cosine(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def assert_no_refusals_but_after_deafness(board) -> None:
    """The board refused no command, unless its emulator thread went unrun for the half
    second after which the driver re-sends the zero command to a silent board (hfabapi's
    wait_online() probe): both copies then wait in the port and merge (error bits 8 and
    256), as they would on a real board that froze. A real board's UART never waits for
    the host's scheduler; this emulator, a thread of the test process, can (seen once in
    CI; holding the test process's GIL for 0.94 s gave three such pairs, for 0.46 s none)."""
    if board.refused:
        assert board.longest_deaf_s >= 0.45, (
            f"the firmware refused commands (error bits {board.refusals}); its port was never "
            f"unread for more than {board.longest_deaf_s * 1000:.0f} ms"
        )
