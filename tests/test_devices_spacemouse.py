"""SpaceMouse driver against emulated devices on emulated hidraw nodes (hidapi's semantics).

Expected values come from spacenavd and libspnav as the test states them, never from
the driver's tables: the device frame is x right, y up, z toward the user.
"""

from __future__ import annotations

import re
import struct
import threading
import time

import numpy as np
import pytest
from sasprobe.devices.base import DeviceFault, DeviceOpenError
from sasprobe.devices.spacemouse import protocol
from sasprobe.devices.spacemouse.driver import SpaceMouseDevice

from tests.conftest import REPO_ROOT
from tests.emulators.hidapi_fake import HidBus, HidModule
from tests.emulators.spacemouse_hid import BY_NAME, SIX_DOF, EmulatedSpaceMouse

# spacenavd src/dev.c usbdb (commit bac572ae), and the universal receiver its vendor rule takes
SPACENAVD_DEVICE_LIST = {
    (0x046D, 0xC603),
    (0x046D, 0xC605),
    (0x046D, 0xC606),
    (0x046D, 0xC621),
    (0x046D, 0xC623),
    (0x046D, 0xC625),
    (0x046D, 0xC626),
    (0x046D, 0xC627),
    (0x046D, 0xC628),
    (0x046D, 0xC629),
    (0x046D, 0xC62B),
    (0x046D, 0xC640),
    (0x256F, 0xC62E),
    (0x256F, 0xC62F),
    (0x256F, 0xC631),
    (0x256F, 0xC632),
    (0x256F, 0xC633),
    (0x256F, 0xC635),
    (0x256F, 0xC636),
    (0x256F, 0xC638),
    (0x256F, 0xC63A),
}
RECEIVER = (0x256F, 0xC652)
# the sign a deflection of each device-frame axis must give: every model, the same motion
AXES = np.eye(3)


@pytest.fixture
def bus():
    bus = HidBus()
    yield bus
    bus.close()


def opened(name: str, bus: HidBus, **options) -> tuple[SpaceMouseDevice, EmulatedSpaceMouse]:
    emu = EmulatedSpaceMouse(name, bus=bus, **options)
    dev = SpaceMouseDevice(emu.path, hid_api=HidModule(bus.directory))
    dev.open()
    return dev, emu


def test_reports_follow_the_public_layout():
    combined = protocol.parse_report(bytes([1]) + struct.pack("<6h", 10, -20, 30, -40, 50, -60))
    assert combined["translation"].tolist() == [10, -20, 30] and combined["rotation"].tolist() == [
        -40,
        50,
        -60,
    ]
    assert protocol.parse_report(bytes([1]) + struct.pack("<3h", 1, 2, 3))[
        "translation"
    ].tolist() == [1, 2, 3]
    assert protocol.parse_report(bytes([2]) + struct.pack("<3h", 4, 5, 6))["rotation"].tolist() == [
        4,
        5,
        6,
    ]
    assert protocol.parse_report(bytes([3, 0x01, 0x02]))["buttons"] == 0x0201
    assert protocol.parse_report(bytes([23, 100])) == {}  # battery level: no motion


@pytest.mark.parametrize("report", [b"", bytes([1, 0, 0]), bytes([2, 1]), bytes([3])])
def test_malformed_reports_are_rejected(report):
    assert protocol.parse_report(report) is None


def test_descriptor_scan_reads_buttons_and_axis_range():
    # written by hand from HID 1.11 §6.2.2: a multi-axis controller, report 1 with X..Rz
    # in -500..500, report 3 with 15 buttons and a 1-bit pad
    descriptor = bytes.fromhex(
        # usage page desktop, usage multi-axis controller, collection (application)
        "05 01 09 08 a1 01"
        "85 01 16 0c fe 26 f4 01 09 30 09 31 09 32 09 33 09 34 09 35 75 10 95 06 81 02"
        "85 03 05 09 19 01 29 0f 15 00 25 01 75 01 95 0f 81 02 95 01 81 01"
        "c0"
    )
    summary = protocol.scan_descriptor(descriptor)
    assert (summary.buttons, summary.axis_maximum) == (15, 500)
    mouse = bytes.fromhex("05 01 09 02 a1 01 05 09 19 01 29 03 75 01 95 03 81 02 c0")
    assert protocol.scan_descriptor(mouse).axis_maximum is None


@pytest.mark.parametrize("product", SIX_DOF, ids=lambda p: p.name)
def test_each_axis_moves_the_cursor_the_way_the_cap_is_pushed(product, bus):
    """Every model of spacenavd's list (and the receiver): a half deflection along each
    device axis moves the cursor along that axis at half speed; a twist turns it about it."""
    dev, emu = opened(product.name, bus)
    try:
        for axis in range(3):
            for sign in (1.0, -1.0):
                emu.hand.deflect(translation=sign * 0.5 * AXES[axis])
                np.testing.assert_allclose(
                    dev.read().velocity_mm_s, sign * 50.0 * AXES[axis], atol=1e-9
                )
                emu.hand.deflect(rotation=sign * 0.5 * AXES[axis])
                before = dev.read().orientation
                time.sleep(0.002)
                after = dev.read().orientation
                turn = (
                    after[1:] * before[0] - before[1:] * after[0] - np.cross(after[1:], before[1:])
                )
                assert np.linalg.norm(turn) > 0
                np.testing.assert_allclose(
                    turn / np.linalg.norm(turn), sign * AXES[axis], atol=1e-9
                )
        emu.hand.release()
        assert np.allclose(dev.read().velocity_mm_s, 0.0)
    finally:
        dev.close()
        emu.close()


@pytest.mark.parametrize(
    "name, key, button",
    [
        # spacenavd bnhack_smpro / bnhack_sment, evdev code → button
        ("SpaceMouse Pro", "menu", 4),
        ("SpaceMouse Pro", "1", 0),
        ("SpaceMouse Pro", "lock", 10),
        ("SpaceMouse Pro", "ctrl", 14),
        ("SpaceMouse Pro Wireless (cable)", "fit", 5),
        ("SpaceMouse Enterprise", "11", 10),
        ("SpaceMouse Enterprise", "V3", 29),
        ("SpaceMouse Enterprise", "space", 26),
        ("SpaceMouse Enterprise", "iso", 30),
        # no remap: the report bit is the button
        ("SpaceNavigator", "right", 1),
        ("SpaceMouse Compact", "left", 0),
        # the receiver: more than two buttons behind it → the SpaceMouse Pro's numbering
        ("Universal Receiver + SpaceMouse Pro Wireless", "menu", 4),
        ("Universal Receiver + SpaceMouse Wireless", "right", 1),
    ],
)
def test_buttons_are_numbered_as_spacenavd_numbers_them(name, key, button, bus):
    dev, emu = opened(name, bus)
    try:
        emu.hand.press(key)
        assert dev.read().buttons == 1 << button
        emu.hand.press()
        assert dev.read().buttons == 0
    finally:
        dev.close()
        emu.close()


def test_a_remapped_model_ignores_the_buttons_its_table_does_not_name(bus):
    dev, emu = opened("SpaceMouse Pro", bus)
    try:
        emu.hand.press(3)  # evdev code 259: not in bnhack_smpro
        assert dev.read().buttons == 0
    finally:
        dev.close()
        emu.close()


def test_the_receiver_names_what_it_guessed(bus):
    plain, emu = opened("Universal Receiver + SpaceMouse Wireless", bus, path=b"/dev/hidraw1")
    pro, emu2 = opened("Universal Receiver + SpaceMouse Pro Wireless", bus, path=b"/dev/hidraw2")
    assert plain.info.model == "SpaceMouse Wireless (universal receiver)"
    assert pro.info.model == "SpaceMouse Pro Wireless (universal receiver)"
    for d, e in ((plain, emu), (pro, emu2)):
        d.close()
        e.close()


def test_the_hidapi_stand_in_blocks_as_hidapi_does(bus):
    """The oracle first: on a handle never set non-blocking, read(n) with timeout 0 waits
    for a report (hid.pyx → hid_read → hid_read_timeout(-1)); unplugging ends it with IOError."""
    emu = EmulatedSpaceMouse("SpaceNavigator", bus=bus)
    handle = HidModule(bus.directory).device()
    handle.open_path(emu.path)
    outcome = []

    def blocking_read():
        try:
            outcome.append(handle.read(64, 0))
        except OSError as exc:
            outcome.append(exc)

    reader = threading.Thread(target=blocking_read, daemon=True)
    reader.start()
    reader.join(0.3)
    assert reader.is_alive(), "a blocking read of a cap at rest returned"
    emu.unplug()
    reader.join(2.0)
    assert not reader.is_alive() and isinstance(outcome[0], OSError)
    handle.close()


def test_reads_never_wait_for_a_cap_at_rest(bus):
    dev, emu = opened("SpaceNavigator", bus)
    states = []
    reader = threading.Thread(
        target=lambda: states.extend(dev.read() for _ in range(100)), daemon=True
    )
    reader.start()
    reader.join(5.0)
    stuck = reader.is_alive()
    emu.unplug()  # releases a reader stuck in a blocking read, so the test itself never hangs
    reader.join(2.0)
    assert not stuck and len(states) == 100
    assert dev._transport._handle.blocking is False
    dev.close()


def test_a_cap_held_off_centre_keeps_moving_the_cursor(bus):
    """Reports come on change only: silence while held is not a release."""
    dev, emu = opened("SpaceMouse Compact", bus)
    try:
        dev.read()
        emu.hand.deflect(translation=(0.5, 0.0, 0.0))
        first = dev.read()
        time.sleep(0.4)  # longer than any "stale" timeout would allow
        held = dev.read()
        assert held.velocity_mm_s[0] == pytest.approx(50.0)
        moved = held.position_mm[0] - first.position_mm[0]
        assert moved == pytest.approx(50.0 * (held.t_ns - first.t_ns) * 1e-9, rel=1e-6)
        emu.hand.release()
        assert dev.read().velocity_mm_s[0] == 0.0
    finally:
        dev.close()
        emu.close()


@pytest.mark.parametrize(
    "name", ["SpaceMouse Compact", "SpaceNavigator"]
)  # 12-byte report 1; reports 1 and 2
def test_rate_control_integrates_the_deflection(name, bus):
    dev, emu = opened(name, bus)
    try:
        first = dev.read()
        emu.hand.deflect(translation=(0.5, 0.0, 0.0), rotation=(0.0, 0.1, 0.0))
        states = [dev.read()]
        for _ in range(20):
            time.sleep(0.005)
            states.append(dev.read())
        emu.hand.release()
        last = dev.read()
        held = (states[-1].t_ns - first.t_ns) * 1e-9
        moved = last.position_mm - first.position_mm
        assert moved[0] == pytest.approx(50.0 * held, rel=1e-6)
        assert abs(moved[1]) < 1e-12 and abs(moved[2]) < 1e-12
        assert np.allclose(last.velocity_mm_s, 0.0)
    finally:
        dev.close()
        emu.close()


def test_full_deflection_follows_the_declared_range(bus):
    dev, emu = opened("SpaceMouse Compact", bus, full_scale=500)
    try:
        emu.hand.deflect(translation=(0.0, 0.0, -1.0))  # pushed fully away from the user
        assert dev.read().velocity_mm_s.tolist() == pytest.approx([0.0, 0.0, -100.0])
        assert dev.info.details["full_scale_counts"] == 500
    finally:
        dev.close()
        emu.close()


def test_spacenavd_dead_zone(bus):
    dev, emu = opened("SpaceMouse Compact", bus)
    try:
        emu.hand.deflect(
            translation=(1 / 350, 0.0, 0.0)
        )  # one count: inside spacenavd's default of 2
        assert dev.read().velocity_mm_s[0] == 0.0
        emu.hand.deflect(translation=(2 / 350, 0.0, 0.0))
        assert dev.read().velocity_mm_s[0] == pytest.approx(100.0 * 2 / 350)
    finally:
        dev.close()
        emu.close()


def test_cursor_stays_in_the_workspace_box(bus):
    emu = EmulatedSpaceMouse("SpaceMouse Compact", bus=bus)
    dev = SpaceMouseDevice(emu.path, hid_api=HidModule(bus.directory), speed_mm_s=20000.0)
    dev.open()
    dev.read()
    emu.hand.deflect(translation=(1.0, -1.0, 1.0))
    for _ in range(20):
        time.sleep(0.002)
        state = dev.read()
    assert np.allclose(state.position_mm, [100.0, -100.0, 100.0])
    dev.close()


def test_input_only_device(bus):
    dev, emu = opened("SpaceMouse Compact", bus)
    assert dev.info.limits.has_force_output is False and dev.info.model == "SpaceMouse Compact"
    dev.write_force([1.0, 2.0, 3.0])  # ignored, never an error
    assert dev.read().calibrated
    dev.close()


def test_malformed_reports_are_counted(bus):
    dev, emu = opened("SpaceMouse Compact", bus)
    for junk in (bytes([1, 0]), bytes([2]), bytes([3])):
        emu.send(junk)
    emu.hand.deflect(translation=(1.0, 0.0, 0.0))
    state = dev.read()
    assert dev.rejected_frames == 3 and state.velocity_mm_s[0] == pytest.approx(100.0)
    dev.close()


def test_only_the_6dof_devices_of_spacenavds_list_are_taken(bus):
    for n, name in enumerate(
        ("CadMouse", "CadMouse Pro", "Keyboard Pro", "Numpad Pro", "Universal Receiver Mouse")
    ):
        EmulatedSpaceMouse(name, bus=bus, path=f"/dev/hidraw1{n}".encode())
    api = HidModule(bus.directory)
    with pytest.raises(DeviceOpenError, match="no 3Dconnexion SpaceMouse found"):
        SpaceMouseDevice(hid_api=api).open()
    cad = EmulatedSpaceMouse("CadMouse", bus=bus, path=b"/dev/hidraw9")
    with pytest.raises(DeviceOpenError, match=r"CadMouse \(256f:c650\) is not a 6-DoF device"):
        SpaceMouseDevice(cad.path, hid_api=api).open()
    EmulatedSpaceMouse("SpaceNavigator", bus=bus, path=b"/dev/hidraw4")
    dev = SpaceMouseDevice(hid_api=api)
    dev.open()  # the one 6-DoF device among them
    assert dev.info.model == "SpaceNavigator" and dev.path == b"/dev/hidraw4"
    dev.close()


def test_the_driver_takes_exactly_spacenavds_list():
    from sasprobe.devices.spacemouse import models

    others = [
        (0x256F, 0xC650),
        (0x256F, 0xC664),
        (0x256F, 0xC665),
        (0x256F, 0xC62C),
        (0x256F, 0xC6FF),
        (0x046D, 0xC077),
        (0x046D, 0xC652),
    ]
    assert {
        ids for ids in SPACENAVD_DEVICE_LIST | set(others) if models.is_six_dof(*ids)
    } == SPACENAVD_DEVICE_LIST
    assert models.is_six_dof(*RECEIVER, (0x01, 0x08)) and not models.is_six_dof(
        *RECEIVER, (0x01, 0x02)
    )


def test_the_documented_udev_rule_opens_only_the_listed_devices():
    readme = (REPO_ROOT / "docs" / "connect-your-arm.md").read_text()
    hidraw_rules = [line for line in readme.splitlines() if line.startswith('KERNEL=="hidraw*"')]
    opened_ids = {
        (int(v, 16), int(p, 16))
        for line in hidraw_rules
        for v, p in re.findall(r"\*:([0-9A-F]{4}):([0-9A-F]{4})\.\*", line)
    }
    assert opened_ids == SPACENAVD_DEVICE_LIST | {RECEIVER}
    assert not any("256f" in line.lower() and "KERNELS" not in line for line in hidraw_rules)


def test_unplugging_faults_and_replugging_recovers(bus):
    dev, emu = opened("SpaceMouse Compact", bus)
    dev.read()
    emu.unplug()
    with pytest.raises(DeviceFault, match="lost"):
        dev.read()
    with pytest.raises(DeviceFault, match="still unavailable"):
        dev.reconnect()
    emu.replug()
    dev.reconnect()
    emu.hand.deflect(translation=(0.0, 1.0, 0.0))
    assert dev.read().velocity_mm_s[1] == pytest.approx(100.0)
    dev.close()


def test_no_spacemouse_is_an_open_error(bus):
    with pytest.raises(DeviceOpenError, match="no 3Dconnexion SpaceMouse found"):
        SpaceMouseDevice(hid_api=HidModule(bus.directory)).open()
    with pytest.raises(DeviceOpenError, match="no HID device at /dev/hidraw-missing"):
        SpaceMouseDevice(b"/dev/hidraw-missing", hid_api=HidModule(bus.directory)).open()


def test_emulator_products_match_the_names_the_test_expects():
    assert {(p.vendor_id, p.product_id) for p in SIX_DOF} == SPACENAVD_DEVICE_LIST | {RECEIVER}
    assert (
        not BY_NAME["SpaceMouse Classic"].y_toward_user and BY_NAME["SpaceNavigator"].y_toward_user
    )
