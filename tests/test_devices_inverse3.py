"""The Inverse3 driver against a stand-in Inverse Service (tests/emulators/inverse_service.py),
a real WebSocket server on loopback.

Expected values come from Haply's published conventions, transcribed here on their own:
Haply's frame is +X right, +Y forward (away from the user), +Z up, in metres
(docs.haply.co commons/basis); sasprobe's is x right, y up, z toward the user, in
millimetres. So a hand moved 10 mm away from the user (Haply +Y) must read −10 mm on z.
"""

from __future__ import annotations

import json
import math
import threading
import time

import numpy as np
import pytest
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.inverse3 import protocol
from sasprobe.devices.inverse3.driver import MAX_IN_FLIGHT, Inverse3Device, create
from websockets.sync.server import serve

from tests.support.driver_loop import balance, settle_against_a_wall
from tests.support.press import wait_for


def to_haply_mm(device_mm):
    x, y, z = device_mm
    return (x, -z, y)


@pytest.fixture
def arm(inverse_service):
    """An emulated service and a driver on it, opened (a reply may be owed 10 ms: 3 periods
    at 300 Hz; `stale_after_s` for another figure)."""
    made = []

    def make(stale_after_s=0.010, **options):
        svc = inverse_service(**options)
        dev = Inverse3Device(svc.url, stale_after_s=stale_after_s)
        dev.open()
        made.append(dev)
        return dev, svc

    yield make
    for dev in made:
        dev.close()


def run(dev, condition=lambda s: True, force=(0.0, 0.0, 0.0), timeout_s=5.0):
    """Tick as the daemon does (read, write) until a read satisfies `condition`; faults are
    counted, not raised (a loaded machine may be late)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            state = dev.read()
        except DeviceFault:
            state = None
        dev.write_force(force)
        if state is not None and condition(state):
            return state
        time.sleep(0.002)
    raise AssertionError("condition not reached in time")


def hold(dev, svc, force):
    """Tick with `force` until the service has taken three more messages: a message in flight
    when the force changed carried the old one, the ones after it carry this one."""
    start = svc.messages
    return run(dev, lambda s: svc.messages >= start + 3, force=force)


def test_the_frame_mapping_gives_the_published_axes():
    np.testing.assert_allclose(protocol.position_mm((0.01, 0.0, 0.0)), [10.0, 0.0, 0.0])  # right
    np.testing.assert_allclose(
        protocol.position_mm((0.0, 0.01, 0.0)), [0.0, 0.0, -10.0]
    )  # away from the user
    np.testing.assert_allclose(protocol.position_mm((0.0, 0.0, 0.01)), [0.0, 10.0, 0.0])  # up
    np.testing.assert_allclose(protocol.haply_force((1.0, 2.0, 3.0)), [1.0, -3.0, 2.0])
    a = 0.6  # a grip turned about Haply's Z (up) is turned about sasprobe's y (up)
    np.testing.assert_allclose(
        protocol.orientation((0.0, 0.0, math.sin(a / 2), math.cos(a / 2))),
        [math.cos(a / 2), 0.0, math.sin(a / 2), 0.0],
        atol=1e-12,
    )


def test_open_names_the_arm_and_centres_its_workspace(arm):
    dev, svc = arm()
    info = dev.info
    assert (info.model, info.serial, info.details["handedness"]) == (
        "Haply Inverse3",
        "049D",
        "right",
    )
    assert info.limits.max_force_n == 2.0 and info.limits.workspace_max_mm[0] == pytest.approx(
        80.0 / math.sqrt(3)
    )
    assert svc.presets == ["arm_front_centered"] and svc.profiles == ["org.sasprobe:daemon"]
    assert svc.basis_changes == 0  # the frame is mapped here, once, not by the service
    state = run(dev)
    np.testing.assert_allclose(
        state.position_mm, [0.0, 0.0, 0.0], atol=1e-9
    )  # the centre, not the base
    assert abs(state.t_ns - time.monotonic_ns()) < 1e9


@pytest.mark.parametrize(
    "device_mm",
    [(10, 0, 0), (-10, 0, 0), (0, 10, 0), (0, -10, 0), (0, 0, 10), (0, 0, -10), (10, -10, 10)],
)
def test_moves_along_each_axis_and_a_diagonal_read_within_half_a_millimetre(arm, device_mm):
    dev, svc = arm()
    svc.hand.target = to_haply_mm(device_mm)
    state = run(
        dev,
        lambda s: (
            np.allclose(svc.hand.position, svc.hand.target)
            and np.linalg.norm(svc.stylus.velocity) < 0.5
        ),
    )
    state = run(dev)  # a state sampled after the cursor came to rest
    np.testing.assert_allclose(state.position_mm, device_mm, atol=0.5)


def test_a_force_is_sent_as_a_vector_in_haplys_frame_and_moves_the_cursor(arm):
    dev, svc = arm()
    state = run(
        dev, lambda s: s.position_mm[2] > 1.99, force=(0.0, 0.0, 1.0)
    )  # toward the user: Haply −Y
    np.testing.assert_allclose(svc.samples[-1][1], [0.0, -1.0, 0.0])
    np.testing.assert_allclose(
        state.position_mm, [0.0, 0.0, 2.0], atol=0.02
    )  # the hand's 0.5 N/mm gives 2 mm
    assert svc.ignored_commands == 0


def test_a_virtual_wall_settles_where_the_hand_and_the_wall_balance(arm):
    dev, svc = arm()
    svc.hand.target = to_haply_mm((14.0, 0.0, 0.0))  # the hand pushes 4 mm through the wall
    x = settle_against_a_wall(dev)
    assert x == pytest.approx(balance(14.0, svc.stylus.hand_k), abs=0.3)


def test_the_grips_buttons_and_orientation(arm):
    dev, svc = arm()
    svc.grip_buttons.update(a=True, c=True)
    svc.grip_orientation = (math.sin(0.3), 0.0, 0.0, math.cos(0.3))  # about Haply's X (right)
    state = run(dev, lambda s: s.buttons == 0b101)
    np.testing.assert_allclose(
        state.orientation, [math.cos(0.3), math.sin(0.3), 0.0, 0.0], atol=1e-12
    )


def test_an_uncalibrated_arm_gets_no_force(arm):
    dev, svc = arm(calibrated=False)
    state = hold(dev, svc, (1.0, 0.0, 0.0))
    assert not state.calibrated and np.allclose(svc.samples[-1][1], 0.0)
    svc.calibrated = True
    run(dev, lambda s: s.calibrated, force=(1.0, 0.0, 0.0))
    hold(dev, svc, (1.0, 0.0, 0.0))
    np.testing.assert_allclose(svc.samples[-1][1], [1.0, 0.0, 0.0])


def test_forces_are_clamped_and_never_nan(arm):
    dev, svc = arm()
    for command in [(50.0, -80.0, 20.0), (np.nan, 0.0, 0.0), (np.inf, 1.0, 1.0)]:
        hold(dev, svc, command)
        sent = svc.samples[-1][1]
        assert np.linalg.norm(sent) <= 2.0 + 1e-9 and np.all(np.isfinite(sent))
    assert np.linalg.norm(svc.samples[-1][1]) == 0.0  # inf: zero


def test_a_hung_service_is_a_fault_once_a_reply_is_owed_too_long_and_recovers(arm):
    dev, svc = arm()
    run(dev, force=(0.0, 0.5, 0.0))
    svc.hang()
    t0 = time.monotonic()
    with pytest.raises(DeviceFault, match="has not answered for"):
        while time.monotonic() - t0 < 1.0:
            dev.read()
            dev.write_force((0.0, 0.5, 0.0))
            time.sleep(0.001)
    with pytest.raises(DeviceFault, match="has not answered for"):
        dev.reconnect()  # too early to give the session up: still a fault, the same session
    svc.resume()
    run(dev)
    assert dev.info.details["sessions"] == 1 and dev.stale_reads >= 1


def test_a_late_service_gets_a_command_every_tick_and_reads_never_wait_for_it(arm):
    """A service whose every answer leaves 50 ms after its message: the driver keeps sending
    one message a tick, several unanswered at once, and each read returns the newest state
    that has arrived (no round trip is waited for)."""
    dev, svc = arm(stale_after_s=0.5, answer_after_s=0.05)
    most_in_flight = states_while_owed = 0
    deadline = time.monotonic() + 20.0

    def unanswered():
        return dev.info.details["messages_sent"] - dev.info.details["replies"]

    while most_in_flight < 3 or states_while_owed < 3:
        assert time.monotonic() < deadline, (most_in_flight, states_while_owed)
        dev.read()
        states_while_owed += unanswered() > 0  # a state, while a reply is still owed
        dev.write_force((0.0, 0.0, 0.0))
        most_in_flight = max(most_in_flight, unanswered())
        time.sleep(0.001)
    assert most_in_flight <= MAX_IN_FLIGHT and dev.held_commands == 0


def test_during_a_hang_the_zero_waits_in_line_behind_the_messages_in_flight(arm):
    """The daemon's ticks go on through a hang: the live forces until the reply is owed 3
    periods (here 3 ms at 1 kHz), then zero, never more than MAX_IN_FLIGHT unanswered. When
    the service answers again it takes them in order, the zero last."""
    dev, svc = arm(stale_after_s=0.003)
    hold(dev, svc, (0.0, 0.5, 0.0))
    wait_for(lambda: np.any(svc.motor_force()), 5.0)
    svc.hang()
    with pytest.raises(DeviceFault, match="has not answered for"):
        while True:  # the daemon's ticks until the read faults
            dev.read()
            dev.write_force((0.0, 0.5, 0.0))
            time.sleep(0.001)
    faults = 0
    for _ in range(20):  # fault ticks: the daemon writes zero
        dev.write_force((0.0, 0.0, 0.0))
        try:
            dev.read()  # a reply already on its way when the service hung may still come
        except DeviceFault:
            faults += 1
        time.sleep(0.001)
    assert faults > 0
    details = dev.info.details
    sent = details["messages_sent"]
    assert sent - details["replies"] <= MAX_IN_FLIGHT
    svc.resume()
    wait_for(lambda: svc.messages == sent, 5.0)  # every message taken, in order ...
    assert np.allclose(svc.samples[-1][1], 0.0)  # ... the zero last
    dev.close()
    wait_for(lambda: not svc._connections, 5.0)  # the service sees the client gone ...
    wait_for(lambda: not np.any(svc.motor_force()), 5.0)  # ... and, uncommanded, the arm idles


def test_a_session_silent_for_a_second_is_replaced(arm):
    dev, svc = arm()
    run(dev)
    svc.hang()
    with pytest.raises(DeviceFault, match="has not answered"):
        deadline = time.monotonic() + 2
        while time.monotonic() < deadline:
            dev.read()
            dev.write_force((0.0, 0.0, 0.0))
            time.sleep(0.002)
    time.sleep(1.1)  # silent past SILENT_RECONNECT_S
    with pytest.raises(DeviceFault, match="reconnecting"):
        dev.reconnect()  # gives the session up, opens a new one in the background
    svc.resume()
    deadline = time.monotonic() + 20  # a wait for the condition: a loaded machine may take long
    while True:
        try:
            dev.reconnect()
            break
        except DeviceFault:
            assert time.monotonic() < deadline, "never reconnected"
            time.sleep(0.05)
    run(dev)
    assert dev.info.details["sessions"] == 2 and svc.sessions == 2


def test_a_closed_connection_is_a_fault_at_once_and_a_new_session_opens_when_the_service_is_back(
    arm,
):
    dev, svc = arm()
    run(dev)
    svc.stop()
    with pytest.raises(DeviceFault, match="closed the connection"):
        deadline = time.monotonic() + 2
        while time.monotonic() < deadline:
            dev.read()
            time.sleep(0.002)
    with pytest.raises(DeviceFault):
        dev.reconnect()
    svc.start()  # the same port
    deadline = time.monotonic() + 20  # a wait for the condition: a loaded machine may take long
    while True:
        try:
            dev.reconnect()
            break
        except DeviceFault:
            assert time.monotonic() < deadline, "never reconnected"
            time.sleep(0.05)
    run(dev)
    assert dev.info.details["sessions"] == 2 and svc.presets == ["arm_front_centered"] * 2


def test_no_service_says_so_in_one_line(inverse_service):
    svc = inverse_service()
    url = svc.url
    svc.close()  # nothing listens on that port now
    with pytest.raises(DeviceOpenError) as err:
        Inverse3Device(url).open()
    message = str(err.value)
    assert "\n" not in message and url in message and "Inverse Service" in message


def _server(greeting):
    server = serve(lambda conn: (conn.send(greeting), conn.recv(timeout=2)), "127.0.0.1", 0)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"ws://127.0.0.1:{server.socket.getsockname()[1]}"


@pytest.mark.parametrize(
    "greeting, refusal",
    [
        (
            json.dumps({"devices": [{"id": 1}]}),
            r"does not speak the Inverse Service's 3.x format \(no 'inverse3' list",
        ),
        ("hello", r"does not speak the Inverse Service's 3.x format \(not JSON"),
        (json.dumps({"session_id": 1, "inverse3": []}), "lists no Inverse3"),
    ],
)
def test_a_service_that_speaks_another_format_is_refused_by_name(greeting, refusal):
    server, url = _server(greeting)
    try:
        with pytest.raises(DeviceOpenError, match=refusal):
            Inverse3Device(url, handshake_timeout_s=1.0).open()
    finally:
        server.shutdown()


def test_close_sends_zero_and_ends_the_session(arm):
    dev, svc = arm()
    run(dev, force=(1.0, 0.0, 0.0))
    messages = svc.messages
    dev.close()
    deadline = time.monotonic() + 2
    while svc._connections and time.monotonic() < deadline:
        time.sleep(0.01)
    assert svc.messages > messages and not svc._connections
    assert np.allclose(svc.samples[-1][1], 0.0) and dev.last_force_n.tolist() == [0.0, 0.0, 0.0]


def test_the_device_string_and_timing():
    assert create(None).url == "ws://localhost:10001"
    dev = create("ws://host:9000", rate_hz=4000)
    assert dev.url == "ws://host:9000" and dev.stale_after_s == pytest.approx(3 / 4000)
