"""The serial arms' drivers (devices/serial_arm.py and each arm's wire format) in closed loop
against their emulated boards behind a real pty: one suite, run for every arm.

Arm-specific behaviour is in test_devices_haply.py and test_devices_woodenhaptics.py, the
known answers from each maker's library in test_devices_*_known.py.
"""

from __future__ import annotations

import select
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from sasprobe.devices import transports
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.registry import open_device

from tests.emulators import haply_serial, woodenhaptics_serial
from tests.support.bounded import join
from tests.support.serial_arm_session import Session, cosine


@dataclass(frozen=True)
class Arm:
    """What the suite needs to know of one arm and its emulated board."""

    scheme: str
    launch: Callable  # the emulator's launch(**options) -> Rig
    variants: dict  # id -> launch options: the models the displacement test covers
    moves: list  # hand moves from the workspace centre (mm) the mechanism can follow
    forces: list  # forces (N) to render; the suite compares the part the mechanism renders
    renderable: Callable  # force -> the part of it the mechanism renders
    aside: tuple  # a hand move (mm) used where any direction will do
    junk: list  # bytes on the line no command asked for
    junk_rejected: int  # at least this many of them are rejected frames
    board_watchdog: bool  # the firmware zeroes its motors when commands stop
    zero_atol_n: float  # what the motors make at a zero command (a PWM step off centre)
    silent_at_open: str  # the open error for a board that never answers (0.5 s), a regex
    planar_axis: int | None = None  # a coordinate the mechanism holds fixed
    refused: Callable = lambda board: (
        0
    )  # commands the board refused (a firmware that refuses none: 0)
    # checks of what only some boards tell; each asserts
    opened: Callable = lambda dev: None  # what the driver learnt when it opened the board
    in_step: Callable = lambda dev, board: (
        None
    )  # a state read just now is the board's latest answer
    replugged: Callable = lambda dev: None  # what a reconnect to a replugged board did
    closed: Callable = lambda board: None  # the board's last command after close()


def _woody_opened(dev) -> None:
    assert dev.info.details["model_code"] == 3


def _woody_in_step(dev, board) -> None:
    assert dev.counts == tuple(board.counters), "a reply older than the board's newest was used"


def _woody_closed(board) -> None:
    assert board.last_command_ma == [0, 0, 0]


def _haply_replugged(dev) -> None:
    assert dev.setups_sent == 2  # a replugged board restarted: it needs the setup again


HAPLY = Arm(
    scheme="haply",
    launch=haply_serial.launch,
    variants={
        "gen3-M0": {"generation": "gen3", "board": "M0"},
        "gen3-M3": {"generation": "gen3", "board": "M3"},
        "gen2-M0": {"generation": "gen2", "board": "M0"},
    },
    moves=[(10, 0, 0), (-10, 0, 0), (0, 0, 10), (0, 0, -10), (7, 0, -7)],
    forces=[
        (0.8, 0.0, 0.0),
        (0.0, 0.0, -0.8),
        (0.5, 0.0, 0.6),
        (0.3, 2.0, -0.4),
    ],  # the last one's Y is dropped
    renderable=lambda f: np.array([f[0], 0.0, f[2]]),
    aside=(0.0, 0.0, 15.0),
    junk=[b"\xff\xfe\xfd", bytes([9]) + np.array([1.0, 2.0], "<f4").tobytes(), bytes([5]) * 3],
    junk_rejected=2,
    board_watchdog=False,
    zero_atol_n=1e-9,
    silent_at_open=r"the board never answered within 0\.5 s",
    planar_axis=1,
    replugged=_haply_replugged,
)

WOODENHAPTICS = Arm(
    scheme="woodenhaptics",
    launch=woodenhaptics_serial.launch,
    variants={"polhem": {"model": 1}, "vintage": {"model": 2}, "woody": {"model": 3}},
    moves=[(10, 0, 0), (-10, 0, 0), (0, 10, 0), (0, -10, 0), (0, 0, 10), (0, 0, -10), (7, -7, 7)],
    forces=[(2.0, 0.0, 0.0), (0.0, -2.0, 0.0), (0.0, 0.0, 2.0), (1.5, 1.0, -2.0)],
    renderable=np.asarray,
    aside=(0.0, 15.0, 0.0),
    junk=[b"junk\n", b"[3,1,2]\n", b"\xff\xfe\n", b"[2,0,0,0,0,0,0,0]\n", b"x" * 300],
    junk_rejected=4,
    board_watchdog=True,
    zero_atol_n=0.01,  # 0 mA is half a PWM step off centre
    silent_at_open=r"never answered the woodenhaptics handshake within 0\.5 s",
    refused=lambda board: board.refused,
    opened=_woody_opened,
    in_step=_woody_in_step,
    closed=_woody_closed,
)

ARMS = {"haply": HAPLY, "woodenhaptics": WOODENHAPTICS}


@pytest.fixture
def rig(request):
    """(arm, driver, board, hand): `request.param` is an arm's name, or (name, launch options)."""
    name, options = request.param if isinstance(request.param, tuple) else (request.param, {})
    arm = ARMS[name]
    rig = arm.launch(**options)
    dev = open_device(rig.device_spec)
    yield arm, dev, rig.board, rig.hand
    dev.close()
    rig.close()


every_arm = pytest.mark.parametrize("rig", list(ARMS), indirect=True)


def session_motor_force(session: Session, board, force) -> np.ndarray:
    """The motors' force at the first tick, rendering `force`, where they exert any."""
    seen = [np.zeros(3)]

    def exerting(_state) -> bool:
        seen[0] = board.motor_force()
        return bool(np.any(seen[0]))

    session.until(exerting, force=force)
    return seen[0]


def check_forces(arm: Arm, session: Session, board, forces) -> None:
    """The force the emulated motors exert is the part of the force written that the
    mechanism renders (cos ≥ 0.99, within 5 %)."""
    for force in forces:
        session.hold(force, board)
        # read between ticks, while the commands flow: a loaded machine may pause the test
        # long enough after hold() for a board's own watchdog to switch the amplifiers off
        made = session_motor_force(session, board, force)
        wanted = arm.renderable(force)
        assert cosine(made, wanted) >= 0.99, (force, made)
        assert np.linalg.norm(made) == pytest.approx(np.linalg.norm(wanted), rel=0.05), (
            force,
            made,
        )


def wait_until(condition, timeout_s: float = 2.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"{what} not reached in {timeout_s:g} s"
        time.sleep(0.002)


def deaf_past_the_silence_probe(dev, board) -> bool:
    """Whether the emulated board went unread for as long as the driver waits before it
    probes a silent board again: the probe's answer then comes on top of the late one, and
    on a line protocol the two commands merge, as they would on a real board that froze
    (serial_arm_session.assert_no_refusals_but_after_deafness)."""
    return board.longest_deaf_s >= 0.9 * dev.silent_after_s


def assert_no_refusals(arm: Arm, dev, board, before: int = 0) -> None:
    if not deaf_past_the_silence_probe(dev, board):
        assert arm.refused(board) == before, (
            f"the firmware refused a command; its port went unread for "
            f"{board.longest_deaf_s * 1000:.0f} ms at most"
        )


def assert_in_step(arm: Arm, dev, board) -> None:
    """Every reply in step with its command and no command refused (unless deaf, above)."""
    if not deaf_past_the_silence_probe(dev, board):
        assert dev.rejected_frames == 0 and dev.resyncs == 0, (
            f"a reply out of step; the board's port went unread for "
            f"{board.longest_deaf_s * 1000:.0f} ms at most"
        )
    assert_no_refusals(arm, dev, board)


@pytest.mark.parametrize(
    "rig",
    [(name, options) for name, arm in ARMS.items() for options in arm.variants.values()],
    indirect=True,
    ids=[f"{name}-{variant}" for name, arm in ARMS.items() for variant in arm.variants],
)
def test_displacements_and_forces_in_the_device_frame(rig):
    arm, dev, board, hand = rig
    dev.open()
    session = Session(dev)
    session.reads_the_stylus(board.stylus)  # the start pose: where the board's counts begin
    hand.target = (0.0, 0.0, 0.0)  # the workspace centre
    centre = session.settle(board.stylus, hand)
    centre_true = board.stylus.now()
    np.testing.assert_allclose(centre.position_mm, centre_true, atol=0.5)
    for move in arm.moves:
        hand.target = move
        state = session.settle(board.stylus, hand)
        true_move = board.stylus.now() - centre_true
        np.testing.assert_allclose(
            true_move, move, atol=0.1
        )  # with no force the stylus rests in the hand
        np.testing.assert_allclose(state.position_mm - centre.position_mm, true_move, atol=0.5)
        if arm.planar_axis is not None:
            assert state.position_mm[arm.planar_axis] == 0.0
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    check_forces(arm, session, board, arm.forces)
    assert_in_step(arm, dev, board)


@every_arm
def test_opening_resends_until_the_board_answers(rig):
    arm, dev, board, _hand = rig
    board.stall(0.35)  # still booting: the firmware reads nothing for 350 ms
    t0 = time.monotonic()
    dev.open()
    assert time.monotonic() - t0 >= 0.3
    arm.opened(dev)
    refused_at_open = arm.refused(board)  # copies that piled up while it booted may have merged
    session = Session(dev)
    session.run(0.3)
    assert_no_refusals(arm, dev, board, before=refused_at_open)  # the session starts in step
    session.reads_the_stylus(board.stylus)


@every_arm
def test_a_board_that_never_answers_is_one_line_and_no_hang(rig):
    arm, dev, board, _hand = rig
    board.go_silent()
    dev.handshake_timeout_s = 0.5
    t0 = time.monotonic()
    with pytest.raises(DeviceOpenError, match=arm.silent_at_open) as err:
        dev.open()
    assert time.monotonic() - t0 < 2.0
    assert "\n" not in str(err.value)


@every_arm
def test_a_stall_of_the_board_is_survived_without_merged_commands_or_stale_reads(rig):
    arm, dev, board, hand = rig
    dev.open()
    session = Session(dev)
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    board.stall(0.2)
    hand.target = arm.moves[0]  # the hand moves on while the board is stalled
    session.run(0.2)
    assert session.faults > 0  # reads fail while it is stalled (the daemon writes zero force)
    session.settle(board.stylus, hand)  # the board is back: reads come again
    last_t = 0
    for _ in range(300):
        state = session.tick()
        if state is None:
            continue
        np.testing.assert_allclose(state.position_mm, board.stylus.now(), atol=0.5)
        if state.t_ns != last_t:  # not the last pose again (a reply a little late)
            arm.in_step(dev, board)
        last_t = state.t_ns
    assert_in_step(
        arm, dev, board
    )  # no second copy went out: no second answer came, nothing merged


@every_arm
def test_a_stalled_host_gets_a_fresh_reply_not_the_waiting_one(rig):
    arm, dev, board, hand = rig
    dev.open()
    session = Session(dev)
    hand.target = (0.0, 0.0, 0.0)
    session.settle(board.stylus, hand)
    dev.write_force((0.0, 0.0, 0.0))  # its reply arrives and waits while the host is away
    hand.target = arm.aside
    time.sleep(0.2)
    if arm.board_watchdog:  # the firmware switches its amplifiers off while the host is away
        wait_until(lambda: board.watchdog_trips >= 1, what="the board's watchdog tripping")
    session.reads_the_stylus(board.stylus)
    assert dev.stale_replies >= 1
    check_forces(arm, session, board, arm.forces[:1])  # the next command switched them on again
    assert_no_refusals(arm, dev, board)


@every_arm
def test_the_watchdogs_zero_never_meets_an_unanswered_command(rig):
    """The daemon's watchdog writes zero (`zero_force_now`) while its loop is stalled. A board
    that has not answered the command in flight has not taken it: on a line protocol a
    second line would meet it in the board's buffer and the firmware would refuse both."""
    arm, dev, board, hand = rig
    dev.open()
    session = Session(dev)
    check_forces(arm, session, board, arm.forces[:1])
    board.stall(0.3)
    time.sleep(0.01)
    with pytest.raises(DeviceFault, match="no reply"):
        for _ in range(5):  # until a command is in flight that the stalled board has not read
            dev.read()
    dev.zero_force_now()  # the loop stalls now: the watchdog's first zero
    time.sleep(0.35)  # the board wakes and answers what it has read
    dev.zero_force_now()  # the watchdog's next try, REZERO_PERIODS later
    wait_until(
        lambda: np.linalg.norm(board.motor_force()) <= arm.zero_atol_n,
        what="zero force on the board",
    )
    assert arm.refused(board) == 0, "the watchdog's zero met the command in flight"
    session.settle(
        board.stylus, hand
    )  # the loop, back, goes on in step: the stylus rests in the hand
    session.reads_the_stylus(board.stylus)


@every_arm
def test_the_watchdogs_zero_leaves_a_read_in_progress_alone(rig, monkeypatch):
    """The watchdog's thread may call `zero_force_now` while the loop's thread is inside a
    read, descheduled there on a busy machine. Here the loop's thread stops for 100 ms right
    after the port said the board's answer is waiting (and the board then stalls); the
    watchdog's zero meanwhile must not take that answer from under the read, which would
    find the port empty and take the cable for pulled."""
    arm, dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    check_forces(arm, session, board, arm.forces[:1])
    session.until(lambda _s: True)
    loop_thread, real_select = threading.current_thread(), select.select

    def descheduled_after_the_answer(rlist, wlist, xlist, timeout=None):
        ready = real_select(rlist, wlist, xlist, timeout)
        if ready[0] and threading.current_thread() is loop_thread:
            board.stall(0.5)  # answered; nothing more comes for a while
            watchdog = threading.Thread(target=_zero_or_busy, args=(dev,))
            watchdog.start()
            join(watchdog)  # the watchdog runs while this thread is away
        return ready

    monkeypatch.setattr(transports.select, "select", descheduled_after_the_answer)
    dev.read_wait_s = dev.reply_timeout_s = 1.0
    dev.write_force((0.0, 0.0, 0.0))
    state = dev.read()  # no DeviceFault: the answer was the read's
    monkeypatch.undo()
    assert state is not None and arm.refused(board) == 0
    time.sleep(0.5)
    dev.zero_force_now()  # the port is free: the zero goes out now
    wait_until(
        lambda: np.linalg.norm(board.motor_force()) <= arm.zero_atol_n,
        what="zero force on the board",
    )


def _zero_or_busy(dev) -> None:
    try:
        dev.zero_force_now()
    except DeviceFault:
        pass  # busy: the watchdog tries again at its next check


@every_arm
def test_a_board_that_stops_mid_session_faults_at_once_and_gets_zero_force(rig):
    arm, dev, board, hand = rig
    dev.open()
    session = Session(dev)
    check_forces(arm, session, board, arm.forces[:1])
    board.go_silent()
    session.run(0.01)  # a reply already on its way may still come
    for _ in range(200):
        t0 = time.monotonic()
        with pytest.raises(DeviceFault, match=f"no reply from the {arm.scheme} arm"):
            dev.read()
        assert time.monotonic() - t0 < 0.05  # each read returns at once
        # a board with a watchdog gets the force on regardless; without one, the zero the
        # daemon writes
        dev.write_force(arm.forces[0] if arm.board_watchdog else (0.0, 0.0, 0.0))
        time.sleep(0.001)
    if arm.board_watchdog:
        assert np.allclose(board.motor_force(), 0.0)  # the firmware's watchdog cut the amplifiers
    board.resume()
    session.settle(
        board.stylus, hand
    )  # the stylus comes to rest in the hand: no force holds it off
    session.reads_the_stylus(board.stylus)
    assert np.linalg.norm(board.motor_force()) <= arm.zero_atol_n


@every_arm
def test_garbage_on_the_line_is_dropped_and_the_session_resynchronises(rig):
    arm, dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    session.run(0.05)
    for junk in arm.junk:
        board.inject(junk)
        session.run(0.05)
    assert dev.rejected_frames >= arm.junk_rejected
    session.reads_the_stylus(board.stylus)
    assert_no_refusals(arm, dev, board)


@every_arm
def test_pulling_the_cable_faults_at_once_and_reconnects(rig):
    arm, dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    session.run(0.05)
    board.unplug()
    t0 = time.monotonic()
    with pytest.raises(DeviceFault, match="lost"):
        for _ in range(3):  # a reply that came before the cable went may still be read
            dev.write_force(arm.forces[0])
            dev.read()
    assert time.monotonic() - t0 < 0.1
    with pytest.raises(DeviceFault, match="still unavailable"):
        dev.reconnect()
    board.replug()  # a replugged board restarted where it was
    dev.reconnect()
    arm.replugged(dev)
    session.reads_the_stylus(board.stylus)


@every_arm
def test_closing_leaves_the_motors_at_zero(rig):
    arm, dev, board, _hand = rig
    dev.open()
    session = Session(dev)
    check_forces(arm, session, board, arm.forces[:1])
    dev.close()
    assert dev.last_force_n.tolist() == [0.0, 0.0, 0.0]
    arm.closed(board)
    wait_until(
        lambda: np.linalg.norm(board.motor_force()) <= arm.zero_atol_n,
        what="zero force on the board",
    )
