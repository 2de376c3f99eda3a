"""The daemon (`sasprobe daemon --device ...`, a real subprocess) driving emulated arms.

The haptic engine is in the loop: the emulated hand pushes the stylus into the
molecule, the daemon renders the contact force, and the emulator's motors must push
back (within the declared limits). The machine these tests share may be too loaded
for 1 kHz, so they assert what happened, never how fast.
"""

from __future__ import annotations

import json
import math
import os
import threading
import time

import numpy as np
import pytest

from sasprobe.devices.haply import HAPLY_2DIY_LIMITS
from sasprobe.devices.woodenhaptics import WOODEN_MODELS
from sasprobe.protocol.client import Subscriber
from sasprobe.protocol.pose import FLAG_CONTACT, FLAG_FAULT
from tests.conftest import REPO_ROOT
from tests.daemon_process import DaemonProcess
from tests.emulators import falcon_usb, libhd, spacemouse_hid
from tests.emulators.haply_serial import Haply2DIYEmulator, start_pose_mm
from tests.emulators.physics import MovableHand
from tests.emulators.woodenhaptics_serial import WoodenHapticsEmulator

def poses_until(sub: Subscriber, condition, daemon: DaemonProcess, timeout_s: float = 60.0):
    """Poll poses until `condition(pose)` holds for one; AssertionError after the timeout."""
    deadline = time.monotonic() + timeout_s
    seen = 0
    while time.monotonic() < deadline:
        for pose in sub.poll(0.1):
            seen += 1
            if condition(pose):
                return pose
    last = sub.pose
    raise AssertionError(f"no such pose among {seen} within {timeout_s} s; last flags "
                         f"{last.flags if last else None}, force {last.force_N if last else None}; "
                         f"daemon stderr: {daemon.stderr[-1500:]}")


@pytest.fixture
def emulators_importable(monkeypatch):
    """The daemon runs in a private folder: let it import tests.emulators for its device."""
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(REPO_ROOT), os.environ.get("PYTHONPATH")])))


def exchanges(emu, n: int, timeout_s: float = 30.0) -> None:
    """Wait until the driver has exchanged `n` more commands with the emulator."""
    target, deadline = emu.replies_sent + n, time.monotonic() + timeout_s
    while emu.replies_sent < target:
        assert time.monotonic() < deadline, "the daemon stopped talking to the arm"
        time.sleep(0.01)


def pushing(pose) -> bool:
    return pose.has(FLAG_CONTACT) and not pose.has(FLAG_FAULT) and np.linalg.norm(pose.force_N) > 0.05


def test_daemon_session_on_the_emulated_serial_arm(tmp_path):
    hand = MovableHand()
    emu = WoodenHapticsEmulator(tmp_path, hand=hand)
    home = tuple(emu.stylus.position)
    hand.target = home  # resting in the home pose: the driver calibrates
    limit = WOODEN_MODELS[3].limits.max_force_n
    try:
        with DaemonProcess(device=f"woodenhaptics:{emu.path}") as daemon:
            assert daemon.ready["device"] == "woodenhaptics"
            sub = Subscriber(daemon.pub)
            poses_until(sub, lambda p: True, daemon)
            exchanges(emu, 100)  # the driver sees the arm resting at home: calibrated
            hand.target = (0.0, 0.0, 0.0)  # into the molecule
            poses_until(sub, pushing, daemon)
            exchanges(emu, 20)  # the force the daemon published has gone out to the arm
            assert emu.max_force_n > 0.05, "the motors never pushed back"
            # the tip the daemon publishes is where the emulated stylus is (both move: agree once)
            poses_until(sub, lambda p: np.linalg.norm(p.tip_mm - emu.stylus.position) < 1.0, daemon)
            assert emu.max_force_n <= limit + 0.05
            assert emu.bad_lines == 0

            emu.unplug()  # pull the cable: force zeroed, fault flagged
            fault = poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon)
            assert np.allclose(fault.force_N, 0.0)
            emu.replug()  # the Teensy restarts: the user brings the arm home and presses its button
            hand.target = home
            deadline = time.monotonic() + 10
            while np.linalg.norm(emu.stylus.position - np.asarray(home)) > 0.5 and time.monotonic() < deadline:
                time.sleep(0.05)
            emu.press_calibration_button()
            exchanges(emu, 100)  # resting at home again
            hand.target = (0.0, 0.0, 0.0)
            poses_until(sub, pushing, daemon)  # reconnected, recalibrated, pushing again
            assert "device reconnected" in daemon.stderr

            rc, report = daemon.stop()
            assert rc == 0, daemon.stderr
            assert report["ticks"] > 0 and report["device_last_force_n"] == [0.0, 0.0, 0.0]
        time.sleep(0.1)
        assert emu.currents.tolist() == [0, 0, 0]  # closing the device left the motors at zero
    finally:
        emu.stop()


def poses_for(sub: Subscriber, seconds: float) -> list:
    poses, deadline = [], time.monotonic() + seconds
    while time.monotonic() < deadline:
        poses += sub.poll(0.05)
    return poses


def test_daemon_presses_the_emulated_falcon_into_the_molecule(monkeypatch, emulators_importable):
    # the user homes the Falcon when its LED is red, then holds the grip at the workspace
    # centre, inside the molecule, with a soft hand (0.1 N/mm) so the force stays moderate
    emu = falcon_usb.launch(hand_stiffness_n_per_mm=0.1)
    hw = emu.hardware
    for name, value in emu.env.items():
        monkeypatch.setenv(name, value)
    try:
        with DaemonProcess(device=emu.device_spec) as daemon:
            assert daemon.ready["device"] == "falcon"
            sub = Subscriber(daemon.pub)
            poses_until(sub, pushing, daemon)
            poses_for(sub, 2.0)  # the grip settles where the motors balance the hand
            poses = [p for p in poses_for(sub, 0.5) if not p.has(FLAG_FAULT)]
            t_first, t_last = poses[0].publish_t_ns, poses[-1].publish_t_ns
            samples = [x for x in list(hw.samples) if t_first <= x.t_ns <= t_last]
            written = np.mean([p.force_N for p in poses], axis=0)
            exerted = np.mean([x.force_n for x in samples], axis=0)
            assert len(poses) > 100 and len(samples) > 100
            assert exerted @ written / np.linalg.norm(exerted) / np.linalg.norm(written) >= 0.99
            assert np.linalg.norm(exerted) == pytest.approx(np.linalg.norm(written), rel=0.05)
            # pushed back out: the grip sits off the hand's target along the force, as far
            # as the hand's spring needs to balance it
            off = np.mean([x.grip_mm for x in samples], axis=0) - np.asarray(emu.hand.target)
            assert off @ exerted / np.linalg.norm(off) / np.linalg.norm(exerted) >= 0.98
            assert np.linalg.norm(off) * 0.1 == pytest.approx(np.linalg.norm(exerted), rel=0.1)

            hw.stall(0.2)  # the Falcon stops answering for 200 ms: zero force, then on by itself
            stalled = poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon)
            assert np.allclose(stalled.force_N, 0.0)
            poses_until(sub, lambda p: pushing(p) and p.seq > stalled.seq, daemon)
            assert hw.upload_attempts == 1 and "device reconnected" not in daemon.stderr

            hw.unplug()  # pull the cable, put it back: a fresh Falcon, firmware and homing again
            fault = poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon)
            assert np.allclose(fault.force_N, 0.0)
            hw.replug()
            back = poses_until(sub, lambda p: "device reconnected" in daemon.stderr, daemon)
            poses_until(sub, lambda p: pushing(p) and p.seq > back.seq, daemon)
            assert hw.upload_attempts == 2 and hw.refused == 0 and hw.homing_losses == 0
            rc, report = daemon.stop()
            assert rc == 0, daemon.stderr
            assert report["device_last_force_n"] == [0.0, 0.0, 0.0]
        assert hw.motor == (0, 0, 0)  # closing left the motors at zero
        assert max(abs(m) for x in hw.samples for m in x.motor) <= 4096
    finally:
        emu.close()


def test_daemon_survives_a_falcon_that_stops_answering(monkeypatch, emulators_importable):
    emu = falcon_usb.launch()
    for name, value in emu.env.items():
        monkeypatch.setenv(name, value)
    try:
        with DaemonProcess(device=emu.device_spec) as daemon:
            sub = Subscriber(daemon.pub)
            poses_until(sub, pushing, daemon)
            emu.hardware.hung = True
            poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon)
            silent = poses_for(sub, 1.0)  # the loop goes on: poses keep coming, all without force
            assert len(silent) > 100 and all(p.has(FLAG_FAULT) and np.allclose(p.force_N, 0.0) for p in silent)
            assert emu.hardware.upload_attempts == 1  # no firmware pushed into a running Falcon
            rc, _report = daemon.stop()
            assert rc == 0, daemon.stderr
            assert "the Falcon has not answered" in daemon.stderr
    finally:
        emu.close()


def test_daemon_session_on_the_emulated_haply(tmp_path):
    hand = MovableHand(start_pose_mm())
    emu = Haply2DIYEmulator(tmp_path, hand=hand)
    try:
        # the whole molecule in the cube, so that the planar arm's plane (the cube's mid-plane) cuts through it
        with DaemonProcess("--cube-half", "fit", device=f"haply:{emu.path}") as daemon:
            sub = Subscriber(daemon.pub)
            poses_until(sub, lambda p: True, daemon)
            hand.target = (0.0, -75.0, 0.0)  # the centre of the pad: the molecule's mid-plane
            pose = poses_until(sub, pushing, daemon)
            assert pose.tip_mm[2] == 0.0  # planar: the driver drops the force's z, the emulator has none
            exchanges(emu, 50)
            assert 0.0 < emu.max_force_n <= HAPLY_2DIY_LIMITS.max_force_n + 1e-3
            rc, _report = daemon.stop()
            assert rc == 0, daemon.stderr
    finally:
        emu.stop()


def test_daemon_takes_the_input_only_spacemouse(monkeypatch):
    emu = spacemouse_hid.launch(product="SpaceNavigator", path=b"/dev/hidraw5")
    for key, value in emu.env.items():
        monkeypatch.setenv(key, value)
    try:
        with DaemonProcess(device=emu.device_spec) as daemon:
            sub = Subscriber(daemon.pub)
            start = poses_until(sub, lambda p: True, daemon)
            emu.hand.deflect(translation=(0.5, 0.0, 0.0))  # held right; the cap sends nothing more
            moved = poses_until(sub, lambda p: p.tip_mm[0] - start.tip_mm[0] > 20.0, daemon)  # 0.4 s at 50 mm/s
            assert abs(moved.tip_mm[1] - start.tip_mm[1]) < 1e-6 and abs(moved.tip_mm[2] - start.tip_mm[2]) < 1e-6
            poses = sub.poll(0.3)
            assert poses and all(np.allclose(p.force_N, 0.0) for p in poses)  # no force output, ever
            emu.unplug()  # the cable pulled: a fault, never a hang
            assert np.allclose(poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon).force_N, 0.0)
            emu.replug()
            back = poses_until(sub, lambda p: "device reconnected" in daemon.stderr and not p.has(FLAG_FAULT), daemon)
            emu.hand.deflect(translation=(0.0, -0.5, 0.0))  # pushed down: the cursor goes down
            poses_until(sub, lambda p: p.tip_mm[1] < back.tip_mm[1] - 5.0, daemon)
            rc, _report = daemon.stop()
            assert rc == 0, daemon.stderr
    finally:
        emu.close()


def test_daemon_on_openhaptics_through_the_stand_in_library(tmp_path, monkeypatch):
    if libhd.build(tmp_path) is None:
        pytest.skip("no C compiler to build the stand-in HD library")
    centre = np.asarray(libhd.USABLE_BOX_CENTRE)  # the cube's centre
    emu = libhd.launch(library=tmp_path / "libHD.so", styles=libhd.HD_CALIBRATION_INKWELL, hand=centre,
                       inkwell=True)
    for key, value in emu.env.items():
        monkeypatch.setenv(key, value)
    swinging = threading.Event()

    def sweep():  # the user swings the stylus ±30 mm along x, through the molecule
        t0 = time.monotonic()
        while not swinging.is_set():
            emu.hand.target = centre + [30.0 * math.sin(math.pi * (time.monotonic() - t0)), 0.0, 0.0]
            time.sleep(0.005)

    hand = threading.Thread(target=sweep, daemon=True)
    hand.start()
    try:
        with DaemonProcess(device=emu.device_spec) as daemon:
            sub = Subscriber(daemon.pub)
            pose = poses_until(sub, pushing, daemon)  # calibrated in the inkwell, then pushed back
            assert np.linalg.norm(pose.force_N) <= 3.3
            emu.wait_frames(20)
            assert 0.05 < emu.control.max_force <= 3.3 + 1e-9 and emu.control.resets == 0
            emu.unplug()
            assert np.allclose(poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon).force_N, 0.0)
            assert emu.applied_force == (0.0, 0.0, 0.0)
            emu.replug()
            back = poses_until(sub, lambda p: "device reconnected" in daemon.stderr, daemon)
            poses_until(sub, lambda p: pushing(p) and p.seq > back.seq, daemon)  # recalibrated, pushing again
            rc, report = daemon.stop()
            assert rc == 0, daemon.stderr
            assert report["device_last_force_n"] == [0.0, 0.0, 0.0]
        assert emu.applied_force == (0.0, 0.0, 0.0)
    finally:
        swinging.set()
        hand.join()
        emu.close()
