"""The Force Dimension driver through ctypes against the stand-in DHD library (fake_libdhd.c).

Expected values come from the published conventions, transcribed here on their own: DHD's
frame is x toward the user, y right, z up, in metres (CHAI3D CMyCustomDevice.cpp
l. 424–427); sasprobe's is x right, y up, z toward the user, in millimetres. So a hand
moved 10 mm toward the user (DHD +x) must read +10 mm on sasprobe's z.
"""

from __future__ import annotations

import json
import math
import os
import time

import numpy as np
import pytest
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.forcedimension import frame
from sasprobe.devices.forcedimension.driver import ForceDimensionDevice, create
from sasprobe.protocol.client import Subscriber
from sasprobe.protocol.pose import FLAG_FAULT

from tests.conftest import run_cli, skip_or_fail
from tests.emulators import libdhd
from tests.support.arm_outage import recorded_outage
from tests.support.daemon_process import DaemonProcess
from tests.support.driver_loop import balance, settle_against_a_wall
from tests.support.press import EMULATED_ARM_RATE, WHOLE, poses_until, pushing, settled
from tests.support.serial_arm_session import cosine


def to_dhd_m(device_mm):
    """sasprobe device frame (mm) → DHD frame (m), from the conventions above."""
    x, y, z = device_mm
    return (z / 1000.0, x / 1000.0, y / 1000.0)


def to_device(dhd_xyz, scale=1.0):
    """DHD frame → sasprobe device frame (times `scale`)."""
    x, y, z = dhd_xyz
    return np.array([y, z, x]) * scale


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    out = libdhd.build(tmp_path_factory.mktemp("libdhd"))
    if out is None:
        skip_or_fail("no C compiler to build the stand-in DHD library")
    return out


@pytest.fixture
def arm(library, monkeypatch):
    """A factory: an emulated arm (options as libdhd.EmulatedDHD) and a driver pointed at it."""
    made = []

    def make(index=0, **options):
        emu = libdhd.launch(library=library, index=index, **options)
        monkeypatch.setenv("FAKE_DHD_CONTROL", str(emu.control_path))
        dev = ForceDimensionDevice(index, library=str(library))
        made.append((dev, emu))
        return dev, emu

    yield make
    for dev, emu in made:
        dev.close()
        emu.close()


def test_the_frame_mapping_gives_the_published_axes():
    np.testing.assert_allclose(
        frame.position_mm((0.01, 0.0, 0.0)), [0.0, 0.0, 10.0]
    )  # toward the user
    np.testing.assert_allclose(frame.position_mm((0.0, 0.01, 0.0)), [10.0, 0.0, 0.0])  # right
    np.testing.assert_allclose(frame.position_mm((0.0, 0.0, 0.01)), [0.0, 10.0, 0.0])  # up
    np.testing.assert_allclose(
        frame.dhd_force((1.0, 2.0, 3.0)), [3.0, 1.0, 2.0]
    )  # right 1, up 2, toward 3
    a = 0.4  # a wrist turned about DHD's z (up) is turned about sasprobe's y (up)
    turned = frame.rotation(
        [[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]]
    )
    np.testing.assert_allclose(
        turned,
        [[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]],
        atol=1e-12,
    )


def test_open_reads_the_model_and_its_limits(arm):
    dev, emu = arm(types=(libdhd.OMEGA3,), serials=(4711,))
    assert dev.info.limits.max_force_n == 8.0  # before opening: the smallest arm's (the Falcon's)
    dev.open()
    info = dev.info
    assert (info.model, info.serial, info.details["system_name"]) == ("omega.3", "4711", "omega.3")
    assert (
        info.limits.max_force_n,
        info.limits.max_stiffness_n_per_mm,
        info.limits.max_damping_n_s_per_m,
    ) == (12.0, 5.0, 30.0)
    assert info.limits.workspace_max_mm[0] == pytest.approx(75.0 / math.sqrt(3.0))
    assert emu.control.force_enabled == 1 and emu.control.enables == 1


@pytest.mark.parametrize(
    "device_mm",
    [(10, 0, 0), (-10, 0, 0), (0, 10, 0), (0, -10, 0), (0, 0, 10), (0, 0, -10), (10, -10, 10)],
)
def test_moves_along_each_axis_and_a_diagonal_read_within_half_a_millimetre(arm, device_mm):
    dev, emu = arm()
    dev.open()
    emu.move_hand(to_dhd_m(device_mm))
    emu.settled()
    state = dev.read()
    np.testing.assert_allclose(state.position_mm, device_mm, atol=0.5)
    assert abs(state.t_ns - time.monotonic_ns()) < 1e9  # the host's monotonic clock


def test_the_sigma7_offset_centres_its_workspace(arm):
    dev, emu = arm(
        types=(libdhd.SIGMA7_RIGHT,), hand=(0.01, -0.02, 0.0)
    )  # CHAI3D adds (-0.01, 0.02, 0)
    dev.open()
    emu.settled()
    np.testing.assert_allclose(dev.read().position_mm, [0.0, 0.0, 0.0], atol=0.05)


def test_a_force_is_rendered_in_dhds_frame_and_moves_the_handle(arm):
    dev, emu = arm()
    dev.open()
    emu.settled()
    dev.write_force([1.0, 0.0, 0.0])  # to the user's right: DHD +y
    assert emu.force_n == (0.0, 1.0, 0.0)
    deadline = time.monotonic() + 5
    while dev.read().position_mm[0] < 1.99 and time.monotonic() < deadline:
        time.sleep(0.005)
    state = dev.read()  # the hand's 500 N/m spring gives way 2 mm to the right
    np.testing.assert_allclose(
        state.position_mm, [1000.0 / libdhd.HAND_STIFFNESS_N_PER_M, 0.0, 0.0], atol=0.02
    )


def test_a_virtual_wall_settles_where_the_hand_and_the_wall_balance(arm):
    dev, emu = arm()
    dev.open()
    emu.move_hand(to_dhd_m((14.0, 0.0, 0.0)))  # the hand pushes 4 mm through the wall
    x = settle_against_a_wall(dev)
    assert x == pytest.approx(balance(14.0, libdhd.HAND_STIFFNESS_N_PER_M / 1000.0), abs=0.3)


def test_timeguard_and_saturation_are_successes(arm):
    dev, emu = arm(timeguard_every=2)
    dev.open()
    emu.control.motor_limit = 0.5
    for _ in range(20):
        dev.read()
        dev.write_force([0.0, 1.0, 0.0])
        time.sleep(0.001)
    assert (
        emu.control.timeguards >= 10
        and dev.info.details["timeguard_reads"] == emu.control.timeguards
    )
    assert emu.control.saturated == 20 and dev.info.details["saturated_writes"] == 20
    assert emu.force_n == pytest.approx((0.0, 0.0, 0.5))


def test_a_velocity_window_without_two_reads_is_no_fault(arm):
    dev, emu = arm()
    dev.open()
    dev.read()
    time.sleep(0.05)  # longer than DHD_VELOCITY_WINDOW (20 ms): dhdGetLinearVelocity times out
    dev.read()
    assert dev.info.details["velocity_estimated"] >= 1
    emu.move_hand(to_dhd_m((0.0, 20.0, 0.0)))  # the hand moves up at 0.4 m/s
    states = []
    for _ in range(30):
        states.append(dev.read())
        time.sleep(0.001)
    assert (
        max(s.velocity_mm_s[1] for s in states) > 100.0
    )  # the library's velocity, in mm/s and on y


def test_forces_are_clamped_and_never_nan(arm):
    dev, emu = arm()
    dev.open()
    rng = np.random.default_rng(3)
    for command in [rng.normal(size=3) * 100 for _ in range(30)] + [[np.nan, 0, 0], [np.inf, 1, 1]]:
        dev.write_force(command)
    assert emu.control.saturated == 0 and emu.control.max_force <= 12.0 + 1e-9
    assert all(math.isfinite(v) for v in emu.force_n)


def test_buttons_and_the_wrist(arm):
    dev, emu = arm(types=(libdhd.OMEGA7_RIGHT,))
    dev.open()
    emu.control.buttons = 0b101
    emu.control.wrist_angle = 0.5  # about DHD's z, up
    state = dev.read()
    assert state.buttons == 0b101
    np.testing.assert_allclose(
        state.orientation, [math.cos(0.25), 0.0, math.sin(0.25), 0.0], atol=1e-12
    )


def test_a_lost_link_is_a_fault_naming_the_error_and_force_is_enabled_again_after(arm):
    dev, emu = arm()
    dev.open()
    dev.write_force([0.0, 0.0, 1.0])
    emu.link(up=False, error=libdhd.DHD_ERROR_TIMEOUT)
    with pytest.raises(DeviceFault, match=r"dhdGetPosition failed: DHD_ERROR_TIMEOUT \(7\)"):
        dev.read()
    with pytest.raises(DeviceFault, match="dhdSetForce failed"):
        dev.write_force([0.0, 0.0, 1.0])
    assert emu.force_n == (0.0, 0.0, 0.0)  # the arm turned its motors off
    with pytest.raises(DeviceFault, match="still unavailable: no Force Dimension arm at index 0"):
        dev.reconnect()
    emu.link(up=True)
    dev.reconnect()
    dev.read()
    dev.write_force([0.0, 0.0, 1.0])
    assert emu.control.enables == 2 and emu.force_n == (1.0, 0.0, 0.0)  # toward the user: DHD +x


def test_close_leaves_the_motors_at_zero(arm):
    dev, emu = arm()
    dev.open()
    dev.write_force([0.0, 2.0, 0.0])
    dev.close()
    assert emu.force_n == (0.0, 0.0, 0.0) and emu.control.open_id == -1
    assert dev.last_force_n.tolist() == [0.0, 0.0, 0.0]


def test_an_index_beyond_the_arms_is_refused(arm):
    dev, _emu = arm(index=1)
    with pytest.raises(DeviceOpenError, match="no Force Dimension arm at index 1: the SDK sees 1"):
        dev.open()


def test_no_library_says_so_in_one_line(monkeypatch, tmp_path):
    monkeypatch.setenv("SASPROBE_DHD_LIBRARY", str(tmp_path / "libdhd.so"))
    with pytest.raises(DeviceOpenError) as err:
        ForceDimensionDevice(0).open()
    message = str(err.value)
    assert (
        "\n" not in message
        and "SASPROBE_DHD_LIBRARY" in message
        and "Force Dimension SDK" in message
    )


def test_a_library_without_dhdsetforce_is_refused_by_name(tmp_path):
    if libdhd.build(tmp_path, "libnoforce.so", without_set_force=True) is None:
        skip_or_fail("no C compiler to build the stand-in DHD library")
    with pytest.raises(
        DeviceOpenError, match="is not the Force Dimension DHD library: it lacks dhdSetForce"
    ):
        ForceDimensionDevice(0, library=str(tmp_path / "libnoforce.so")).open()


def test_the_device_string():
    assert create(None).index == 0 and create("2").index == 2
    with pytest.raises(DeviceOpenError, match="expected an arm index"):
        create("omega")


def test_devices_lists_the_arms_the_library_counts_and_checks_one(library, tmp_path):
    emu = libdhd.launch(
        library=library,
        types=(libdhd.OMEGA3, libdhd.SIGMA7_RIGHT),
        serials=(4711, 12),
        hand=(0.0, 0.01, 0.0),
    )
    env = dict(os.environ, **emu.env)
    try:
        listed = run_cli("devices", "--json", env=env)
        assert listed.returncode == 0, listed.stderr
        arms = [
            (d["path"], d["description"], d["device"])
            for d in json.loads(listed.stdout)["devices"]
            if d["transport"] == "dhd"
        ]
        assert arms == [
            ("index 0", "Force Dimension omega.3 serial 4711", "forcedimension"),
            ("index 1", "Force Dimension sigma.7 (right) serial 12", "forcedimension:1"),
        ]
        checked = run_cli(
            "devices", "--check", "forcedimension:1", "--seconds", "0.3", "--json", env=env
        )
        assert checked.returncode == 0, checked.stderr
        report = json.loads(checked.stdout)
        assert (
            report["info"]["model"] == "sigma.7 (right)"
            and report["reads"] > 10
            and report["faults"] == 0
        )
        # the hand holds the handle 10 mm right of DHD's origin; the sigma.7's offset adds 20 mm
        np.testing.assert_allclose(report["position_mm"], [30.0, 0.0, -10.0], atol=0.1)
        assert emu.control.open_id == -1 and emu.force_n == (0.0, 0.0, 0.0)  # closed, at zero
    finally:
        emu.close()


def test_check_without_the_library_is_one_line(tmp_path):
    result = run_cli(
        "devices",
        "--check",
        "forcedimension",
        env=dict(os.environ, SASPROBE_DHD_LIBRARY=str(tmp_path / "libdhd.so")),
    )
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "SASPROBE_DHD_LIBRARY" in lines[0], (
        result.stderr
    )


def test_daemon_presses_the_emulated_omega_and_rides_out_a_lost_link(
    library, tmp_path, monkeypatch
):
    emu = libdhd.launch(
        library=library, hand=(0.0, 0.0, 0.03)
    )  # 30 mm above the workspace centre: outside
    for key, value in emu.env.items():
        monkeypatch.setenv(key, value)
    path = tmp_path / "session.mcap"
    try:
        with DaemonProcess(
            *EMULATED_ARM_RATE, *WHOLE, "--record", str(path), device=emu.device_spec
        ) as daemon:
            assert daemon.ready["device"] == "forcedimension"
            sub = Subscriber(daemon.pub)
            poses_until(sub, lambda p: p.tip_mm[1] > 29.0, daemon)
            emu.move_hand((0.0, 0.0, 0.0))  # down to the centre, into the molecule
            poses_until(sub, pushing, daemon)
            settled(sub, daemon)
            written, exerted, held = [], [], []
            end = time.monotonic() + 0.5
            while time.monotonic() < end:
                poses = sub.poll(0.02)
                if poses and not poses[-1].has(FLAG_FAULT):
                    written.append(poses[-1].force_N)
                    exerted.append(to_device(emu.force_n))
                    held.append(to_device(np.subtract(emu.handle_m, emu.control.hand), 1000.0))
            assert len(written) > 10, daemon.stderr[-1500:]
            wrote, made = np.median(written, axis=0), np.median(exerted, axis=0)
            assert cosine(made, wrote) >= 0.99 and np.linalg.norm(made) == pytest.approx(
                np.linalg.norm(wrote), rel=0.05
            ), (made, wrote)
            assert (
                np.median(held, axis=0) @ wrote / np.linalg.norm(wrote) > 1.0
            )  # pushed out of the surface

            failed_at = time.monotonic_ns()
            emu.link(up=False)  # the arm stops answering: every call fails with DHD_ERROR_COM
            assert np.allclose(poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon).force_N, 0.0)
            time.sleep(0.3)
            emu.link(up=True)
            poses_until(sub, lambda p: "device reconnected" in daemon.stderr, daemon)
            emu.move_hand(
                (0.0, 0.0, 0.03)
            )  # out into free space (a reconnected probe starts unseated), back in
            poses_until(sub, lambda p: p.tip_mm[1] > 29.0 and not p.has(FLAG_FAULT), daemon)
            emu.move_hand((0.0, 0.0, 0.0))
            poses_until(sub, pushing, daemon)
            rc, report = daemon.stop()
            assert rc == 0, daemon.stderr
            assert report["device_last_force_n"] == [0.0, 0.0, 0.0]
        assert emu.force_n == (0.0, 0.0, 0.0) and emu.control.open_id == -1
        assert (
            emu.control.timeguards > 0 and emu.control.enables >= 2
        )  # force enabled again after the outage
        outage = recorded_outage(path, failed_at)
        assert any(e and "DHD_ERROR_COM" in e for e in outage["errors"])
        assert "reconnect" in [e["cmd"] for e in outage["session"].events]
    finally:
        emu.close()
