"""`sasprobe devices` and every bad --device input, through the real CLI."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from types import SimpleNamespace

import pytest
from sasprobe.devices import registry
from sasprobe.devices.base import HapticDevice
from sasprobe.devices.discovery import discover

from tests.conftest import REPO_ROOT, run_cli
from tests.emulators.falcon_usb import EmulatedUsbBackend, FalconHardware
from tests.emulators.hidapi_fake import HidBus, HidModule
from tests.emulators.libhd import build as build_libhd
from tests.emulators.spacemouse_hid import EmulatedSpaceMouse
from tests.emulators.woodenhaptics_serial import WoodenHapticsEmulator
from tests.support.serial_arm_session import assert_no_refusals_but_after_deafness

FALCON_BACKEND = "tests.emulators.falcon_usb:backend_from_environment"


def one_line_error(result, *fragments):
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sasprobe: error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    assert "Traceback" not in result.stderr


def test_devices_lists_the_emulated_devices_it_was_shown(tmp_path, monkeypatch):
    """`sasprobe devices` in a subprocess, pointed at emulators this test set up: each
    6-DoF device, the Falcon and the HD library are listed with the strings written
    here; the CadMouse, keyboard and the receiver's mouse interface are not."""
    bus = HidBus()
    for path, name in [
        (b"/dev/hidraw3", "SpaceNavigator"),
        (b"/dev/hidraw4", "SpaceMouse Enterprise"),
        (b"/dev/hidraw5", "Universal Receiver + SpaceMouse Wireless"),
        (b"/dev/hidraw6", "Universal Receiver Mouse"),
        (b"/dev/hidraw7", "CadMouse"),
        (b"/dev/hidraw8", "Keyboard Pro"),
        (b"/dev/hidraw9", "SpaceMouse Classic"),
    ]:
        EmulatedSpaceMouse(name, path=path, bus=bus)
    monkeypatch.setenv("SASPROBE_HID_API", "tests.emulators.hidapi_fake:module_from_environment")
    monkeypatch.setenv("SASPROBE_HID_BUS", str(bus.directory))
    monkeypatch.setenv("PYTHONPATH", str(REPO_ROOT))
    emulated_falcon(monkeypatch, tmp_path)
    library = build_libhd(tmp_path)
    if library is not None:
        monkeypatch.setenv("SASPROBE_HD_LIBRARY", str(library))
    result = run_cli("devices", "--json")
    assert result.returncode == 0, result.stderr
    listed = json.loads(result.stdout)
    hid = [
        (d["path"], d["vendor_id"], d["product_id"], d["description"], d["device"])
        for d in listed["devices"]
        if d["transport"] == "hid"
    ]
    assert hid == [
        ("/dev/hidraw3", "046d", "c626", "SpaceNavigator", "spacemouse:/dev/hidraw3"),
        ("/dev/hidraw4", "256f", "c633", "SpaceMouse Enterprise", "spacemouse:/dev/hidraw4"),
        (
            "/dev/hidraw5",
            "256f",
            "c652",
            "3Dconnexion Universal Receiver",
            "spacemouse:/dev/hidraw5",
        ),
        ("/dev/hidraw9", "046d", "c606", "SpaceMouse Classic", "spacemouse:/dev/hidraw9"),
    ]
    usb = [
        (d["vendor_id"], d["product_id"], d["description"], d["device"])
        for d in listed["devices"]
        if d["transport"] == "usb"
    ]
    assert usb == [("0403", "cb48", "Novint Falcon", "falcon")]
    if library is not None:
        assert f"OpenHaptics HD library found ({library})" in " ".join(listed["notes"])
    text = run_cli("devices")
    assert text.returncode == 0, text.stderr
    assert "046d:c626  SpaceNavigator\n       --device spacemouse:/dev/hidraw3" in text.stdout
    assert "0403:cb48  Novint Falcon\n       --device falcon" in text.stdout
    for absent in ("CadMouse", "Keyboard", "hidraw6", "hidraw7", "hidraw8"):
        assert absent not in text.stdout
    bus.close()


def test_devices_without_any_device_says_none_found(tmp_path, monkeypatch):
    monkeypatch.setenv("SASPROBE_HID_API", "tests.emulators.hidapi_fake:module_from_environment")
    bus = HidBus()
    monkeypatch.setenv("SASPROBE_HID_BUS", str(bus.directory))
    monkeypatch.setenv("PYTHONPATH", str(REPO_ROOT))
    emulated_falcon(monkeypatch, tmp_path, unplugged=True)
    result = run_cli("devices", "--json")
    bus.close()
    assert result.returncode == 0, result.stderr
    assert not [d for d in json.loads(result.stdout)["devices"] if d["transport"] in ("hid", "usb")]


def test_checking_a_cadmouse_is_refused_in_one_line(monkeypatch):
    emu = EmulatedSpaceMouse("CadMouse", path=b"/dev/hidraw7")
    for key, value in emu.env.items():
        monkeypatch.setenv(key, value)
    try:
        one_line_error(
            run_cli("devices", "--check", "spacemouse:/dev/hidraw7"),
            "CadMouse (256f:c650) is not a 6-DoF device",
        )
        one_line_error(
            run_cli("devices", "--check", "spacemouse"), "no 3Dconnexion SpaceMouse found"
        )
    finally:
        emu.close()


def test_check_reads_an_emulated_spacemouse_end_to_end(monkeypatch):
    emu = EmulatedSpaceMouse("SpaceMouse Pro", path=b"/dev/hidraw2")
    for key, value in emu.env.items():
        monkeypatch.setenv(key, value)
    result = run_cli("devices", "--check", emu.device_spec, "--seconds", "0.3", "--json")
    emu.close()
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert (
        report["info"]["model"] == "SpaceMouse Pro"
        and report["faults"] == 0
        and report["reads"] > 20
    )
    assert report["info"]["details"]["usb_id"] == "046d:c62b"


def test_discovery_reports_each_emulated_device_with_its_device_string(tmp_path):
    ports = [
        SimpleNamespace(device="/dev/ttyACM0", vid=0x16C0, pid=0x0483, description="USB Serial"),
        SimpleNamespace(device="/dev/ttyACM1", vid=0x0301, pid=0x2988, description="Touch"),
        SimpleNamespace(device="/dev/ttyUSB0", vid=0x0403, pid=0x6001, description="FT232R"),
        SimpleNamespace(device="/dev/ttyS0", vid=None, pid=None, description="n/a"),
    ]
    bus = HidBus()
    EmulatedSpaceMouse("SpaceMouse Compact", path=b"/dev/hidraw7", bus=bus)
    EmulatedSpaceMouse("CadMouse Pro", path=b"/dev/hidraw8", bus=bus)
    falcon = EmulatedUsbBackend(FalconHardware(b"fw"))
    found, notes = discover(
        comports=lambda: ports, hid_api=HidModule(bus.directory), usb_backend=falcon
    )
    bus.close()
    assert [(f.transport, f.device) for f in found] == [
        ("serial", "woodenhaptics:/dev/ttyACM0"),
        ("serial", "openhaptics"),
        ("serial", "woodenhaptics:/dev/ttyUSB0"),
        ("hid", "spacemouse:/dev/hidraw7"),
        ("usb", "falcon"),
    ]
    assert any("/dev/ttyS0" in n for n in notes)


@pytest.mark.parametrize(
    "spec",
    [
        "falcon",
        "woodenhaptics:/dev/ttyACM0",
        "haply:/dev/ttyACM0",
        "spacemouse",
        "openhaptics:Default PHANToM",
    ],
)
def test_every_scheme_accepts_the_daemon_options_without_opening(spec):
    device = registry.open_device(spec, structure=object(), rate_hz=1000.0, seed=1)
    assert isinstance(device, HapticDevice)
    assert device.info.limits.max_force_n >= 0


def test_unknown_device():
    one_line_error(
        run_cli("devices", "--check", "phantom:1"), "unknown device 'phantom:1'", "falcon"
    )


def test_missing_port():
    one_line_error(
        run_cli("devices", "--check", "woodenhaptics:/dev/ttyACM99"), "no such serial port"
    )
    one_line_error(run_cli("devices", "--check", "haply"), "haply needs a serial port")


def test_permission_denied_on_the_device_node(tmp_path):
    emu = WoodenHapticsEmulator(tmp_path)
    try:
        os.chmod(os.path.realpath(emu.path), 0)
        args = [sys.executable, "-m", "sasprobe", "devices", "--check", f"woodenhaptics:{emu.path}"]
        if os.geteuid() == 0:  # root ignores file modes: drop the capability that lets it
            if not shutil.which("setpriv"):
                pytest.skip("running as root without setpriv")
            args = ["setpriv", "--bounding-set", "-dac_override,-dac_read_search", *args]
        result = subprocess.run(args, capture_output=True, text=True, timeout=60, cwd=REPO_ROOT)
        one_line_error(result, "permission denied", "dialout", "udev rule")
    finally:
        emu.stop()


def test_missing_firmware_file(tmp_path):
    one_line_error(
        run_cli("devices", "--check", f"falcon:{tmp_path / 'falcon.bin'}"),
        "Falcon firmware file not found",
    )


def test_missing_vendor_library(tmp_path, monkeypatch):
    monkeypatch.setenv("SASPROBE_HD_LIBRARY", str(tmp_path / "libHD.so"))
    one_line_error(run_cli("devices", "--check", "openhaptics"), "OpenHaptics is not installed")


def emulated_falcon(monkeypatch, tmp_path, unplugged=False):
    """Point subprocesses' Falcon driver at the emulator; returns the firmware file."""
    firmware = tmp_path / "fw.bin"
    firmware.write_bytes(os.urandom(1000))
    monkeypatch.setenv("SASPROBE_USB_BACKEND", FALCON_BACKEND)
    monkeypatch.setenv("SASPROBE_FALCON_EMU_FIRMWARE", str(firmware))
    if unplugged:
        monkeypatch.setenv("SASPROBE_FALCON_EMU_UNPLUGGED", "1")
    return firmware


def test_no_falcon_attached(tmp_path, monkeypatch):
    firmware = emulated_falcon(monkeypatch, tmp_path, unplugged=True)
    one_line_error(run_cli("devices", "--check", f"falcon:{firmware}"), "no Novint Falcon found")


def test_check_drives_an_emulated_serial_arm_end_to_end(tmp_path):
    emu = WoodenHapticsEmulator(tmp_path)
    try:
        result = run_cli(
            "devices", "--check", f"woodenhaptics:{emu.path}", "--seconds", "0.5", "--json"
        )
        assert result.returncode == 0, result.stderr
        report = json.loads(result.stdout)
        assert report["info"]["model"] == "WoodenHaptics Woody" and report["reads"] > 50
        assert report["calibrated"] is True  # it rested in its home pose
        # every command the board got was well formed; a reply late by more than the read's
        # 10 ms wait (a loaded machine) is a fault of its own, never a merged command after it
        assert_no_refusals_but_after_deafness(emu)
        assert report["faults"] <= 0.05 * report["reads"], report["first_fault"]
        assert report["faults"] == 0 or report["first_fault"].startswith(
            "no reply from the woodenhaptics arm"
        )
        # the states came from the board's replies: a read hands back the previous pose only
        # when a reply is up to two periods late (devices/serial_arm.py), so most are fresh
        assert emu.replies_sent >= 0.8 * report["reads"]
    finally:
        emu.stop()


def test_check_uploads_firmware_to_an_emulated_falcon(tmp_path, monkeypatch):
    firmware = emulated_falcon(monkeypatch, tmp_path)
    result = run_cli("devices", "--check", f"falcon:{firmware}", "--seconds", "0.5", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["info"]["details"]["firmware_uploads"] == 1 and report["reads"] > 50
    # a reply later than the read's timeout (a loaded machine: the emulator's thread waits
    # for the CPU) is a fault of its own, counted; nothing else may fail
    assert report["faults"] <= 0.05 * report["reads"], report["first_fault"]
    assert report["faults"] == 0 or report["first_fault"].startswith(
        "the Falcon has not answered for"
    ), report["first_fault"]


def test_last_force_is_what_was_asked_after_clamping_and_zero_after_close(tmp_path):
    emu = WoodenHapticsEmulator(tmp_path)
    try:
        device = registry.open_device(f"woodenhaptics:{emu.path}")
        device.open()
        device.read()
        device.write_force([100.0, 0.0, 0.0])
        assert device.last_force_n.tolist() == [device.info.limits.max_force_n, 0.0, 0.0]
        device.close()
        assert device.last_force_n.tolist() == [0.0, 0.0, 0.0]
    finally:
        emu.stop()


@pytest.mark.parametrize("spec", ["woodenhaptics:/dev/ttyACM99", "haply:/dev/ttyACM99"])
def test_the_daemon_without_its_arm_says_one_line(spec):
    """Nothing before the open error: a device that never opened was sent no force."""
    one_line_error(run_cli("daemon", "--device", spec, "--seconds", "1"), "no such serial port")
