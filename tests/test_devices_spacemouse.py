"""SpaceMouse driver against an emulated puck behind a fake at the hidapi boundary."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest

from sasprobe.devices import spacemouse as S
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from tests.emulators.spacemouse_hid import EmulatedSpaceMouse, FakeHidApi


def test_reports_follow_the_public_layout():
    combined = S.parse_report(bytes([1]) + struct.pack("<6h", 10, -20, 30, -40, 50, -60))
    assert combined["translation"].tolist() == [10, -20, 30] and combined["rotation"].tolist() == [-40, 50, -60]
    assert S.parse_report(bytes([1]) + struct.pack("<3h", 1, 2, 3))["translation"].tolist() == [1, 2, 3]
    assert S.parse_report(bytes([2]) + struct.pack("<3h", 4, 5, 6))["rotation"].tolist() == [4, 5, 6]
    assert S.parse_report(bytes([3, 0x01, 0x02]))["buttons"] == 0x0201
    assert S.parse_report(bytes([0x17, 100, 1, 0])) == {}  # battery: not ours


@pytest.mark.parametrize("report", [b"", bytes([1, 0, 0]), bytes([2, 1]), bytes([3])])
def test_malformed_reports_are_rejected(report):
    assert S.parse_report(report) is None


def test_known_ids():
    assert S.is_spacemouse(0x046D, 0xC626) and S.is_spacemouse(0x256F, 0xABCD)
    assert not S.is_spacemouse(0x046D, 0xC077)  # a Logitech mouse


@pytest.fixture
def rig():
    puck = EmulatedSpaceMouse()
    api = FakeHidApi(puck)
    dev = S.SpaceMouseDevice(hid_api=api)
    yield dev, puck, api
    dev.close()


def integrate(dev, seconds):
    states = []
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        states.append(dev.read())
        time.sleep(0.002)
    return states


def test_input_only_device(rig):
    dev, puck, _api = rig
    dev.open()
    assert dev.info.limits.has_force_output is False and dev.info.model == "SpaceMouse Compact"
    dev.write_force([1.0, 2.0, 3.0])  # ignored, never an error
    state = dev.read()
    assert state.calibrated and np.allclose(state.position_mm, 0.0)


@pytest.mark.parametrize("combined", [True, False])
def test_rate_control_moves_the_cursor_at_the_deflection_speed(combined):
    puck = EmulatedSpaceMouse(combined_reports=combined)
    dev = S.SpaceMouseDevice(hid_api=FakeHidApi(puck), speed_mm_s=100.0)
    dev.open()
    first = dev.read()
    puck.move([175, 0, 0], [0, 0, 0])  # half deflection to the right
    states = [first]
    for _ in range(40):
        time.sleep(0.005)
        puck.move([175, 0, 0], [0, 0, 0])  # the cap repeats reports while held
        states.append(dev.read())
    puck.move([0, 0, 0], [0, 0, 0])  # released
    states.append(dev.read())
    moved = states[-1].position_mm - first.position_mm
    held = (states[-2].t_ns - states[1].t_ns) * 1e-9
    # 50 mm/s while held: each read integrates the rate over the time since the previous read
    assert moved[0] == pytest.approx(50.0 * held, rel=0.2, abs=0.2)
    assert abs(moved[1]) < 1e-9 and abs(moved[2]) < 1e-9
    assert states[-2].velocity_mm_s[0] == pytest.approx(50.0)
    assert np.allclose(states[-1].velocity_mm_s, 0.0)
    dev.close()


def test_axes_map_to_the_device_frame(rig):
    dev, puck, _api = rig
    dev.open()
    puck.move([0, 350, -350], [0, 0, 0])  # cap pulled toward the user and lifted
    v = dev.read().velocity_mm_s
    assert v == pytest.approx([0.0, 100.0, 100.0])


def test_twist_turns_the_cursor(rig):
    dev, puck, _api = rig
    dev.open()
    dev.read()
    for _ in range(30):
        puck.move([0, 0, 0], [0, 0, -350])  # twist about the cap's vertical axis → +Y
        time.sleep(0.005)
        state = dev.read()
    q = state.orientation
    assert np.linalg.norm(q) == pytest.approx(1.0)
    axis = q[1:] / np.linalg.norm(q[1:])
    assert axis == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)


def test_cursor_stays_in_the_workspace_box(rig):
    dev, puck, _api = rig
    dev = S.SpaceMouseDevice(hid_api=_api, speed_mm_s=20000.0)
    dev.open()
    dev.read()
    for _ in range(20):
        puck.move([350, 350, 350], [0, 0, 0])
        time.sleep(0.002)
        state = dev.read()
    assert np.allclose(state.position_mm, [100.0, -100.0, 100.0])
    dev.close()


def test_buttons_and_deadband(rig):
    dev, puck, _api = rig
    dev.open()
    puck.press(0b10)
    puck.move([5, -6, 7], [3, 0, -2])  # resting drift inside the deadband
    state = dev.read()
    assert state.buttons == 0b10 and np.allclose(state.velocity_mm_s, 0.0)


def test_a_lost_report_stream_stops_the_cursor(rig):
    dev, puck, _api = rig
    dev.stale_s = 0.05
    dev.open()
    puck.move([350, 0, 0], [0, 0, 0])
    assert dev.read().velocity_mm_s[0] > 0
    time.sleep(0.1)  # no further report: treated as released
    assert dev.read().velocity_mm_s[0] == 0.0


def test_malformed_reports_are_counted(rig):
    dev, puck, _api = rig
    dev.open()
    for junk in (bytes([1, 0]), bytes([2]), bytes([3])):
        puck.push(junk)
    puck.move([350, 0, 0], [0, 0, 0])
    state = dev.read()
    assert dev.rejected_frames == 3 and state.velocity_mm_s[0] == pytest.approx(100.0)


def test_unplugging_faults_and_replugging_recovers(rig):
    dev, puck, _api = rig
    dev.open()
    dev.read()
    puck.unplug()
    with pytest.raises(DeviceFault):
        dev.read()
    with pytest.raises(DeviceFault, match="still unavailable"):
        dev.reconnect()
    puck.replug()
    dev.reconnect()
    dev.read()


def test_no_spacemouse_is_an_open_error():
    with pytest.raises(DeviceOpenError, match="no 3Dconnexion SpaceMouse found"):
        S.SpaceMouseDevice(hid_api=FakeHidApi()).open()
    with pytest.raises(DeviceOpenError, match="cannot open"):
        S.SpaceMouseDevice(b"/dev/hidraw-missing", hid_api=FakeHidApi()).open()
