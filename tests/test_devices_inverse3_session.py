"""The Inverse3 as the daemon and `sasprobe devices` see it, against a stand-in Inverse
Service (tests/emulators/inverse_service.py): the rate the daemon runs it at, discovery and
the check, and a press through the daemon that rides out a hung and a closed service.
Haply's frame (+X right, +Y away from the user, +Z up, metres; docs.haply.co commons/basis)
is transcribed here on its own.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np
import pytest
from sasprobe.daemon.config import DaemonConfig
from sasprobe.daemon.session_setup import prepare_session
from sasprobe.protocol.client import Subscriber
from sasprobe.protocol.pose import FLAG_FAULT

from tests.conftest import run_cli
from tests.support.arm_outage import recorded_outage
from tests.support.daemon_process import DaemonProcess
from tests.support.press import WHOLE, poses_until, pushing, settled
from tests.support.serial_arm_session import cosine


def test_the_arm_runs_at_the_rate_it_declares_and_a_reply_may_be_owed_three_periods():
    """No tick waits on the service's round trip: the arm runs at the daemon's 1 kHz by
    default and up to 4 kHz, and how long a reply may be owed follows the loop's rate."""
    start = prepare_session(
        DaemonConfig(device="inverse3:ws://127.0.0.1:9")
    )  # creates, never connects
    limits = start.device.info.limits
    assert start.rate_hz == limits.nominal_rate_hz == 1000.0 and limits.max_rate_hz == 4000.0
    assert start.device.stale_after_s == pytest.approx(0.003)
    given = prepare_session(DaemonConfig(device="inverse3:ws://127.0.0.1:9", rate_hz=4000.0))
    assert given.rate_hz == 4000.0 and given.device.stale_after_s == pytest.approx(0.00075)


def test_devices_lists_the_services_arm_and_checks_it(inverse_service):
    svc = inverse_service(calibrated=False)
    svc.hand.target = (0.0, 0.0, 10.0)  # 10 mm up
    env = dict(os.environ, **svc.env)
    listed = run_cli("devices", "--json", env=env)
    assert listed.returncode == 0, listed.stderr
    arms = [
        (d["path"], d["description"], d["device"], d["note"])
        for d in json.loads(listed.stdout)["devices"]
        if d["transport"] == "websocket"
    ]
    assert arms == [
        (
            svc.url,
            "Haply Inverse3 049D",
            f"inverse3:{svc.url}",
            "not calibrated yet: let it self-calibrate",
        )
    ]
    assert svc.messages == 0  # listing sends nothing
    checked = run_cli(
        "devices", "--check", f"inverse3:{svc.url}", "--seconds", "0.3", "--json", env=env
    )
    assert checked.returncode == 0, checked.stderr
    report = json.loads(checked.stdout)
    # reads, not a rate: a loaded machine may give the check only a few ticks
    assert (
        report["info"]["model"] == "Haply Inverse3"
        and report["reads"] >= 1
        and report["calibrated"] is False
    )
    np.testing.assert_allclose(report["position_mm"], [0.0, 10.0, 0.0], atol=0.5)
    assert np.allclose(svc.samples[-1][1], 0.0)  # the check wrote zero force


def test_check_without_a_service_is_one_line(inverse_service):
    svc = inverse_service()
    url = svc.url
    svc.close()
    result = run_cli("devices", "--check", f"inverse3:{url}")
    lines = result.stderr.strip().splitlines()
    assert (
        result.returncode == 2
        and len(lines) == 1
        and url in lines[0]
        and "Inverse Service" in lines[0]
    ), result.stderr


NEW_SESSION = "opening a new session"  # the driver's warning when a silent service is given up


def press_and_settle(svc, sub, daemon) -> tuple[list, int]:
    """Down to the workspace centre, into the molecule: the poses of a settled press, and the
    sessions the driver opened meanwhile. A loaded machine may starve the stand-in service
    (a thread of this process) for over a second, and the driver then opens a new session,
    whose probe starts unseated: the hand is lifted into free space and pressed again."""
    before = daemon.stderr.count(NEW_SESSION)
    for _ in range(3):
        opened = daemon.stderr.count(NEW_SESSION)
        svc.hand.target = (0.0, 0.0, 0.0)
        poses_until(sub, pushing, daemon)
        try:
            return settled(sub, daemon, timeout_s=20.0), daemon.stderr.count(NEW_SESSION) - before
        except AssertionError:
            if daemon.stderr.count(NEW_SESSION) == opened:
                raise
        svc.hand.target = (0.0, 0.0, 30.0)
        poses_until(sub, lambda p: p.tip_mm[1] > 29.0 and not p.has(FLAG_FAULT), daemon)
    raise AssertionError(f"no settled press in three tries; daemon stderr: {daemon.stderr[-1500:]}")


def test_daemon_presses_the_emulated_inverse3_and_rides_out_a_hung_and_a_closed_service(
    inverse_service, tmp_path
):
    svc = inverse_service()
    svc.hand.place((0.0, 0.0, 30.0))  # 30 mm above the workspace centre: outside the molecule
    path = tmp_path / "session.mcap"
    with DaemonProcess(
        *PRESS_RATE, *WHOLE, "--record", str(path), device=svc.device_spec
    ) as daemon:
        assert daemon.ready["device"] == "inverse3"
        sub = Subscriber(daemon.pub)
        poses_until(sub, lambda p: p.tip_mm[1] > 29.0, daemon)
        poses, starved_sessions = press_and_settle(svc, sub, daemon)
        t_first, t_last = poses[0].publish_t_ns, poses[-1].publish_t_ns
        samples = [x for x in list(svc.samples) if t_first <= x[0] <= t_last]
        wrote = np.median([p.force_N for p in poses], axis=0)
        made = np.median([to_device(x[1]) for x in samples], axis=0)  # on the service's own record
        assert len(samples) > 20 and svc.ignored_commands == 0  # half a second at 100 Hz
        assert cosine(made, wrote) >= 0.99 and np.linalg.norm(made) == pytest.approx(
            np.linalg.norm(wrote), rel=0.05
        )
        held = np.median(
            [to_device(x[2]) for x in samples], axis=0
        )  # the cursor, the hand at the origin
        assert held @ wrote / np.linalg.norm(wrote) > 1.0  # pushed out of the surface

        hung_at = time.monotonic_ns()
        svc.hang()  # the service stops answering, then answers again: no new session needed
        assert np.allclose(poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon).force_N, 0.0)
        time.sleep(0.3)
        svc.resume()
        poses_until(sub, pushing, daemon)
        closed_at = time.monotonic_ns()
        svc.stop()  # the service goes away, connection and all, then comes back
        assert np.allclose(poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon).force_N, 0.0)
        time.sleep(0.3)
        svc.start()
        poses_until(sub, lambda p: "device reconnected" in daemon.stderr, daemon)
        svc.hand.target = (
            0.0,
            0.0,
            30.0,
        )  # out into free space (a reconnected probe starts unseated), back in
        poses_until(sub, lambda p: p.tip_mm[1] > 29.0 and not p.has(FLAG_FAULT), daemon)
        svc.hand.target = (0.0, 0.0, 0.0)
        poses_until(sub, pushing, daemon)
        rc, report = daemon.stop()
        assert rc == 0, daemon.stderr
        assert report["device_last_force_n"] == [0.0, 0.0, 0.0]
    assert svc.sessions == 2 + starved_sessions  # the hang needed none, the closed service one
    hung = recorded_outage(path, hung_at)
    assert any(e and "has not answered" in e for e in hung["errors"])
    closed = recorded_outage(path, closed_at)
    assert any(e and "closed the connection" in e for e in closed["errors"])
    assert [e["cmd"] for e in closed["session"].events].count("reconnect") == 1


# The stand-in service is a thread of this test process. With the 2-core machine loaded
# (load average 13 seen), its replies came later than the driver's 2.5 periods at 250 Hz
# (10 ms) many times a second, each a fault that restarts the daemon's force ramp, and the
# press never held still for half a second. At 100 Hz a reply may take 25 ms.
PRESS_RATE = ("--rate", "100")


def to_device(haply):
    """Haply's frame → sasprobe's device frame, from the conventions above (same units)."""
    x, y, z = haply
    return np.array([x, z, -y])
