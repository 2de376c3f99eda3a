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
from tests.emulators.spacemouse_hid import EmulatedSpaceMouse, FakeHidApi
from tests.emulators.woodenhaptics_serial import WoodenHapticsEmulator

FALCON_BACKEND = "tests.emulators.falcon_usb:backend_from_environment"


def one_line_error(result, *fragments):
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sasprobe: error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    assert "Traceback" not in result.stderr


def test_devices_lists_what_discovery_finds():
    result = run_cli("devices", "--json")
    assert result.returncode == 0, result.stderr
    listed = json.loads(result.stdout)
    found, _notes = discover()
    assert [d["device"] for d in listed["devices"]] == [f.device for f in found]
    text = run_cli("devices")
    assert text.returncode == 0
    if not found:
        assert text.stdout.startswith("none found")
    else:
        for f in found:
            assert f"--device {f.device}" in text.stdout


def test_discovery_reports_each_emulated_device_with_its_device_string(tmp_path):
    ports = [SimpleNamespace(device="/dev/ttyACM0", vid=0x16C0, pid=0x0483, description="USB Serial"),
             SimpleNamespace(device="/dev/ttyACM1", vid=0x0301, pid=0x2988, description="Touch"),
             SimpleNamespace(device="/dev/ttyUSB0", vid=0x0403, pid=0x6001, description="FT232R"),
             SimpleNamespace(device="/dev/ttyS0", vid=None, pid=None, description="n/a")]
    puck = EmulatedSpaceMouse(path=b"/dev/hidraw7")
    falcon = EmulatedUsbBackend(FalconHardware(b"fw"))
    found, notes = discover(comports=lambda: ports, hid_api=FakeHidApi(puck), usb_backend=falcon)
    assert [(f.transport, f.device) for f in found] == [
        ("serial", "woodenhaptics:/dev/ttyACM0"), ("serial", "openhaptics"), ("serial", "woodenhaptics:/dev/ttyUSB0"),
        ("hid", "spacemouse:/dev/hidraw7"), ("usb", "falcon")]
    assert any("/dev/ttyS0" in n for n in notes)


@pytest.mark.parametrize("spec", ["falcon", "woodenhaptics:/dev/ttyACM0", "haply:/dev/ttyACM0", "spacemouse",
                                  "openhaptics:Default PHANToM"])
def test_every_scheme_accepts_the_daemon_options_without_opening(spec):
    device = registry.open_device(spec, structure=object(), rate_hz=1000.0, seed=1)
    assert isinstance(device, HapticDevice)
    assert device.info.limits.max_force_n >= 0


def test_unknown_device():
    one_line_error(run_cli("devices", "--check", "phantom:1"), "unknown device 'phantom:1'", "falcon")


def test_missing_port():
    one_line_error(run_cli("devices", "--check", "woodenhaptics:/dev/ttyACM99"), "no such serial port")
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
    one_line_error(run_cli("devices", "--check", f"falcon:{tmp_path / 'falcon.bin'}"),
                   "Falcon firmware file not found")


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
        result = run_cli("devices", "--check", f"woodenhaptics:{emu.path}", "--seconds", "0.5", "--json")
        assert result.returncode == 0, result.stderr
        report = json.loads(result.stdout)
        assert report["info"]["model"] == "WoodenHaptics Woody" and report["reads"] > 50
        assert report["faults"] == 0 and report["calibrated"] is True  # it rested in its home pose
        assert emu.replies_sent >= report["reads"]
    finally:
        emu.stop()


def test_check_uploads_firmware_to_an_emulated_falcon(tmp_path, monkeypatch):
    firmware = emulated_falcon(monkeypatch, tmp_path)
    result = run_cli("devices", "--check", f"falcon:{firmware}", "--seconds", "0.5", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["info"]["details"]["firmware_uploads"] == 1 and report["reads"] > 50 and report["faults"] == 0


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
