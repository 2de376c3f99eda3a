"""The daemon (`sasprobe daemon --device ...`, a real subprocess) driving emulated arms.

The haptic engine is in the loop: the emulated hand pushes the stylus into the
molecule, the daemon renders the contact force, and the emulator's motors must push
back (within the declared limits). The machine these tests share may be too loaded
for 1 kHz, so they assert what happened, never how fast.
"""

from __future__ import annotations

import math
import os
import threading
import time

import numpy as np
import pytest
from sasprobe.protocol.client import ControlClient, Subscriber
from sasprobe.protocol.pose import FLAG_FAULT

from tests.conftest import REPO_ROOT, skip_or_fail
from tests.emulators import falcon_usb, haply_serial, libhd, spacemouse_hid, woodenhaptics_serial
from tests.support.bounded import join
from tests.support.daemon_process import DaemonProcess
from tests.support.press import (
    EMULATED_ARM_RATE,
    WHOLE,
    poses_for,
    poses_until,
    pushing,
    settled,
    wait_for,
)
from tests.support.serial_arm_session import assert_no_refusals_but_after_deafness, cosine


@pytest.fixture
def emulators_importable(monkeypatch):
    """The daemon runs in a private folder: let it import tests.emulators for its device."""
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join(filter(None, [str(REPO_ROOT), os.environ.get("PYTHONPATH")]))
    )


def pressed_and_pushed_back(sub: Subscriber, daemon: DaemonProcess, board, plane=(0, 1, 2)) -> None:
    """Hold the press until it has settled, then compare the force the daemon wrote with the
    force the emulated motors exerted over the same time (means; the part the mechanism can
    render: `plane`), and check that it holds the stylus out of the surface. Both sides
    come from their own records (the poses, the board's samples), so a test process that
    runs late samples nothing out of step."""
    poses_until(sub, pushing, daemon)
    poses = settled(sub, daemon)
    t_first, t_last = poses[0].publish_t_ns, poses[-1].publish_t_ns
    samples = [x for x in list(board.samples) if t_first <= x.t_ns <= t_last]
    assert len(samples) > 10, daemon.stderr[-1500:]
    mask = np.zeros(3)
    mask[list(plane)] = 1.0
    wrote = np.mean([p.force_N for p in poses], axis=0) * mask
    exerted = np.mean([x.force_n for x in samples], axis=0)
    assert cosine(exerted, wrote) >= 0.99, (exerted, wrote)
    assert np.linalg.norm(exerted) == pytest.approx(np.linalg.norm(wrote), rel=0.05), (
        exerted,
        wrote,
    )
    held_out = np.mean(
        [x.stylus_mm - x.hand_mm for x in samples], axis=0
    )  # the motors hold the stylus off the hand
    assert held_out @ wrote / np.linalg.norm(wrote) > 1.0, held_out


def test_daemon_presses_the_emulated_woody_into_the_molecule(tmp_path):
    rig = woodenhaptics_serial.launch(directory=tmp_path)
    board, hand = rig.board, rig.hand
    try:
        hand.target = (
            0.0,
            35.0,
            0.0,
        )  # from its home pose to above the molecule, before the daemon starts
        wait_for(lambda: np.linalg.norm(board.stylus.now() - hand.target) < 0.5)
        with DaemonProcess(*EMULATED_ARM_RATE, *WHOLE, device=rig.device_spec) as daemon:
            assert daemon.ready["device"] == "woodenhaptics"
            sub = Subscriber(daemon.pub)
            poses_until(sub, lambda p: np.linalg.norm(p.tip_mm - board.stylus.now()) < 1.0, daemon)
            hand.target = (0.0, 0.0, 0.0)  # down into the molecule
            pressed_and_pushed_back(sub, daemon, board)
            assert_no_refusals_but_after_deafness(board)

            board.unplug()  # pull the cable: force zeroed, fault flagged
            fault = poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon)
            assert np.allclose(fault.force_N, 0.0)
            hand.target = (
                board.arm.tip_m(board.arm.home_bodies()) * 1000.0
            )  # back to its home pose to power up
            wait_for(lambda: np.linalg.norm(board.stylus.now() - hand.target) < 0.5)
            board.replug()
            poses_until(sub, lambda p: "device reconnected" in daemon.stderr, daemon)
            hand.target = (0.0, 0.0, 0.0)
            poses_until(sub, pushing, daemon)  # reconnected, pushing again

            rc, report = daemon.stop()
            assert rc == 0, daemon.stderr
            assert report["ticks"] > 0 and report["device_last_force_n"] == [0.0, 0.0, 0.0]
        assert board.last_command_ma == [0, 0, 0]  # closing the device left the motors at zero
    finally:
        rig.close()


def test_daemon_presses_the_emulated_falcon_into_the_molecule(monkeypatch, emulators_importable):
    # the user homes the Falcon when its LED is red, then holds the grip at the workspace
    # centre, inside the molecule, with a soft hand (0.1 N/mm) so the force stays moderate
    emu = falcon_usb.launch(hand_stiffness_n_per_mm=0.1)
    hw = emu.hardware
    for name, value in emu.env.items():
        monkeypatch.setenv(name, value)
    try:
        with DaemonProcess(*EMULATED_ARM_RATE, *WHOLE, device=emu.device_spec) as daemon:
            assert daemon.ready["device"] == "falcon"
            sub = Subscriber(daemon.pub)
            poses_until(sub, pushing, daemon)
            poses = settled(sub, daemon)  # the grip comes to rest where the motors balance the hand
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
        with DaemonProcess(*WHOLE, device=emu.device_spec) as daemon:
            sub = Subscriber(daemon.pub)
            poses_until(sub, pushing, daemon)
            emu.hardware.hung = True
            poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon)
            silent = poses_for(sub, 1.0)  # the loop goes on: poses keep coming, all without force
            assert len(silent) > 100 and all(
                p.has(FLAG_FAULT) and np.allclose(p.force_N, 0.0) for p in silent
            )
            assert emu.hardware.upload_attempts == 1  # no firmware pushed into a running Falcon
            # the fault the daemon names is the Falcon's silence (on a loaded machine a slow
            # read may have begun the fault before it, and the log says a fault once)
            with ControlClient(daemon.ctl, timeout_s=30) as client:
                deadline = time.monotonic() + 30
                while "the Falcon has not answered" not in (
                    client.status()["device"]["last_fault"] or ""
                ):
                    assert time.monotonic() < deadline, client.status()["device"]
                    time.sleep(0.1)
            rc, _report = daemon.stop()
            assert rc == 0, daemon.stderr
    finally:
        emu.close()


def test_daemon_presses_the_emulated_haply_into_the_molecule(tmp_path):
    rig = haply_serial.launch(directory=tmp_path)
    board, hand = rig.board, rig.hand
    try:
        # the planar arm's plane (the cube's mid-plane) cuts through the whole molecule
        with DaemonProcess(*EMULATED_ARM_RATE, *WHOLE, device=rig.device_spec) as daemon:
            sub = Subscriber(daemon.pub)
            poses_until(sub, lambda p: True, daemon)
            hand.target = (0.0, 0.0, 0.0)  # the centre of the pad: into the molecule's mid-plane
            pressed_and_pushed_back(sub, daemon, board, plane=(0, 2))  # the pad renders no Y
            assert sub.pose.tip_mm[1] == 0.0
            rc, _report = daemon.stop()
            assert rc == 0, daemon.stderr
        assert np.allclose(
            board.motor_force(), 0.0
        )  # the board has no watchdog: closing wrote zero
    finally:
        rig.close()


def test_daemon_takes_the_input_only_spacemouse(monkeypatch):
    emu = spacemouse_hid.launch(product="SpaceNavigator", path=b"/dev/hidraw5")
    for key, value in emu.env.items():
        monkeypatch.setenv(key, value)
    try:
        with DaemonProcess(*WHOLE, device=emu.device_spec) as daemon:
            sub = Subscriber(daemon.pub)
            start = poses_until(sub, lambda p: True, daemon)
            emu.hand.deflect(translation=(0.5, 0.0, 0.0))  # held right; the cap sends nothing more
            moved = poses_until(
                sub, lambda p: p.tip_mm[0] - start.tip_mm[0] > 20.0, daemon
            )  # 0.4 s at 50 mm/s
            assert (
                abs(moved.tip_mm[1] - start.tip_mm[1]) < 1e-6
                and abs(moved.tip_mm[2] - start.tip_mm[2]) < 1e-6
            )
            poses = sub.poll(0.3)
            assert poses and all(
                np.allclose(p.force_N, 0.0) for p in poses
            )  # no force output, ever
            emu.unplug()  # the cable pulled: a fault, never a hang
            assert np.allclose(poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon).force_N, 0.0)
            emu.replug()
            back = poses_until(
                sub,
                lambda p: "device reconnected" in daemon.stderr and not p.has(FLAG_FAULT),
                daemon,
            )
            emu.hand.deflect(translation=(0.0, -0.5, 0.0))  # pushed down: the cursor goes down
            poses_until(sub, lambda p: p.tip_mm[1] < back.tip_mm[1] - 5.0, daemon)
            rc, _report = daemon.stop()
            assert rc == 0, daemon.stderr
    finally:
        emu.close()


def test_daemon_on_openhaptics_through_the_stand_in_library(tmp_path, monkeypatch):
    if libhd.build(tmp_path) is None:
        skip_or_fail("no C compiler to build the stand-in HD library")
    centre = np.asarray(libhd.USABLE_BOX_CENTRE)  # the cube's centre
    emu = libhd.launch(
        library=tmp_path / "libHD.so",
        styles=libhd.HD_CALIBRATION_INKWELL,
        hand=centre,
        inkwell=True,
    )
    for key, value in emu.env.items():
        monkeypatch.setenv(key, value)
    swinging = threading.Event()

    def sweep():  # the user swings the stylus ±30 mm along x, through the molecule
        t0 = time.monotonic()
        while not swinging.is_set():
            emu.hand.target = centre + [
                30.0 * math.sin(math.pi * (time.monotonic() - t0)),
                0.0,
                0.0,
            ]
            time.sleep(0.005)

    hand = threading.Thread(target=sweep, daemon=True)
    hand.start()
    try:
        with DaemonProcess(*WHOLE, device=emu.device_spec) as daemon:
            sub = Subscriber(daemon.pub)
            pose = poses_until(sub, pushing, daemon)  # calibrated in the inkwell, then pushed back
            assert np.linalg.norm(pose.force_N) <= 3.3
            emu.wait_frames(20)
            assert 0.05 < emu.control.max_force <= 3.3 + 1e-9 and emu.control.resets == 0
            emu.unplug()
            assert np.allclose(poses_until(sub, lambda p: p.has(FLAG_FAULT), daemon).force_N, 0.0)
            wait_for(
                lambda: emu.applied_force == (0.0, 0.0, 0.0), timeout_s=2.0
            )  # its motors are off
            emu.replug()
            back = poses_until(sub, lambda p: "device reconnected" in daemon.stderr, daemon)
            poses_until(
                sub, lambda p: pushing(p) and p.seq > back.seq, daemon
            )  # recalibrated, pushing again
            rc, report = daemon.stop()
            assert rc == 0, daemon.stderr
            assert report["device_last_force_n"] == [0.0, 0.0, 0.0]
        assert emu.applied_force == (0.0, 0.0, 0.0)
    finally:
        swinging.set()
        join(hand)
        emu.close()
