"""An OpenHaptics arm as the daemon and `sasprobe devices` see it, through the stand-in HD
library (fake_libhd.c): its identity, and the workspace the navigation cube maps onto."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from sasprobe.protocol.client import ControlError, Subscriber

from tests.conftest import run_cli
from tests.emulators import libhd
from tests.emulators.libhd import HD_CALIBRATION_AUTO
from tests.support.daemon_process import DaemonProcess


def test_devices_check_shows_the_serial_number_the_library_serves(hd_library, monkeypatch):
    emu = libhd.launch(library=hd_library, styles=HD_CALIBRATION_AUTO, serial="41150100123")
    for key, value in emu.env.items():
        monkeypatch.setenv(key, value)
    try:
        result = run_cli("devices", "--check", emu.device_spec, "--seconds", "0.2")
        assert result.returncode == 0, result.stderr
        assert "  serial     41150100123\n" in result.stdout
        report = json.loads(
            run_cli("devices", "--check", emu.device_spec, "--seconds", "0.2", "--json").stdout
        )
        assert report["info"]["serial"] == "41150100123"
    finally:
        emu.close()


# The makers' nominal workspaces: Touch/Omni 160 x 120 x 70 mm (the emulator's model 0 has
# that size), Desktop 160 x 120 x 120 mm, Premium 1.5 381 x 267 x 191 mm; the navigation
# cube maps onto the cube inscribed in the usable box, of half its smallest edge.
@pytest.mark.parametrize("model, half_mm", [("touch", 35.0), ("desktop", 60.0), ("premium", 95.5)])
def test_the_navigation_cube_maps_onto_the_cube_inscribed_in_the_arms_usable_box(
    hd_library, monkeypatch, model, half_mm
):
    emu = libhd.launch(
        library=hd_library, styles=HD_CALIBRATION_AUTO, model=model
    )  # the hand at the library origin
    for key, value in emu.env.items():
        monkeypatch.setenv(key, value)
    try:
        with DaemonProcess("--cube-half", "20", device=emu.device_spec) as daemon:
            sub = Subscriber(daemon.pub)
            try:
                box = sub.wait_for_scene(30.0)["device"]["limits"]
            except ControlError as exc:
                raise AssertionError(f"{exc}; daemon stderr: {daemon.stderr[-1500:]}") from None
            assert (
                min(np.subtract(box["workspace_max_mm"], box["workspace_min_mm"])) / 2.0 == half_mm
            )
            deadline = time.monotonic() + 10.0
            poses = []
            while not poses and time.monotonic() < deadline:
                poses = [p for p in sub.poll(0.1) if np.linalg.norm(p.tip_mm) > 10.0]
            assert poses, daemon.stderr
            pose = poses[-1]
            # goal = cube centre + (cube half edge / inscribed half edge) · tip, the view unturned
            mapped = (
                pose.cube_half_A
                * np.linalg.norm(pose.tip_mm)
                / np.linalg.norm(pose.goal_A - pose.cube_center_A)
            )
            assert mapped == pytest.approx(half_mm, rel=1e-6)
            np.testing.assert_allclose(
                pose.goal_A - pose.cube_center_A,
                pose.tip_mm * pose.cube_half_A / half_mm,
                atol=1e-9,
            )
    finally:
        emu.close()
