"""OpenHaptics force output after a force error, against the stand-in HD library
(fake_libhd.c): force comes back only once the stylus is out of the contact, whichever way
it left (ErrorHandling.c, danepowell/openhaptics commit 2ce9a48,
examples/HD/console/ErrorHandling, l. 279-303: contact is allowed again once the device is
on the free side), or a button is pressed anew (AnchoredSpringForce.c l. 196-202,
227-233), and then ramps in.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from tests.emulators.libhd import (
    HD_CALIBRATION_AUTO,
    HD_DEVICE_BUTTON_1,
    HD_EXCEEDED_MAX_FORCE,
    USABLE_BOX_CENTRE,
)
from tests.support.driver_loop import read_until


# The daemon's wall in these tests: the plane x = 0 of the library frame (the usable box's
# centre has x = 0, so device x = library x), free space toward +x, its force pushing the
# stylus out along +x. The emulator's hand holds the stylus on a 0.5 N/mm spring, the arm's
# maximum stiffness: a force F moves the stylus F / 0.5 mm toward +x.
def held_at(x_mm):
    return (x_mm, 0.0, USABLE_BOX_CENTRE[2])


def command_at(dev, emu, x_mm, force):
    """One tick as the daemon runs it with the stylus at x_mm: read that state, write `force`
    (the daemon's force for it), let the servo loop render it."""
    read_until(dev, lambda s: s.position_mm[0] == pytest.approx(x_mm))
    dev.write_force(force)
    emu.wait_frames(3)
    return emu.applied_force


def withheld_at(dev, emu, x_mm):
    """A tick whose force the daemon withheld (late, or a ramp's first): read, then zero that
    says nothing of the contact."""
    read_until(dev, lambda s: s.position_mm[0] == pytest.approx(x_mm))
    dev.withhold_force()
    emu.wait_frames(3)
    return emu.applied_force


def wait_for_force(emu, force, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while emu.applied_force != tuple(force):
        assert time.monotonic() < deadline, f"the motors render {emu.applied_force}, not {force}"
        time.sleep(0.002)


def stopped_by_a_force_error(hd_arm, hand_x, force, stylus_x, buttons=0):
    dev, emu = hd_arm(styles=HD_CALIBRATION_AUTO, hand=held_at(hand_x))
    emu.control.buttons = buttons
    dev.open()
    read_until(dev, lambda s: s.calibrated)
    dev.write_force(force)
    read_until(dev, lambda s: s.position_mm[0] == pytest.approx(stylus_x))
    emu.inject(HD_EXCEEDED_MAX_FORCE)
    emu.wait_frames(5)
    assert emu.applied_force == (0.0, 0.0, 0.0) and dev.info.details["force_stopped"] is True
    return dev, emu


def test_in_a_soft_contact_force_comes_back_only_on_the_free_side_and_ramps_in(hd_arm):
    """ErrorHandling.c l. 279-303: after a force error, contact comes back only once the device
    is on the free side. A wall five times softer than the arm's stiffest (0.1 N/mm) holds the
    stylus 10 mm in at 1 N; pulled back 4 mm, twice as far as 1 N could press it in at the
    arm's 0.5 N/mm, it is still 6 mm in. Zeros that say nothing of the contact (the
    watchdog's during a stall, a late tick's) must not bring the force back there."""
    dev, emu = stopped_by_a_force_error(hd_arm, hand_x=-12.0, force=(1.0, 0.0, 0.0), stylus_x=-10.0)
    assert command_at(dev, emu, -12.0, (1.2, 0.0, 0.0)) == (
        0.0,
        0.0,
        0.0,
    )  # the hand pushes in: no force
    emu.hand.target = held_at(-6.0)  # pulled back 4 mm: still 6 mm in
    assert command_at(dev, emu, -6.0, (0.6, 0.0, 0.0)) == (0.0, 0.0, 0.0)
    dev.zero_force_now()  # the loop stalls: the watchdog's zero
    emu.wait_frames(3)
    for _ in range(5):  # the loop back, its first ticks late: force withheld, the stylus in
        assert withheld_at(dev, emu, -6.0) == (0.0, 0.0, 0.0)
    assert command_at(dev, emu, -6.0, (0.6, 0.0, 0.0)) == (
        0.0,
        0.0,
        0.0,
    )  # still pressed in: no force
    assert dev.info.details["force_stopped"] is True

    emu.hand.target = held_at(2.0)  # out of the wall: the daemon asks for no force there
    for _ in range(3):
        command_at(dev, emu, 2.0, (0.0, 0.0, 0.0))
    assert dev.info.details["force_stopped"] is False
    emu.hand.target = held_at(-6.0)  # back in: the contact's force ramps in, never a step
    command_at(dev, emu, -6.0, (0.0, 0.0, 0.0))
    emu.control.max_step = 0.0
    dev.write_force((0.6, 0.0, 0.0))
    wait_for_force(emu, (0.6, 0.0, 0.0))
    assert 0.0 < emu.control.max_step <= 0.01  # N per servo frame


def test_a_new_button_press_brings_force_back_ramped_even_after_a_stall(hd_arm):
    """AnchoredSpringForce.c l. 196-202, 227-233: a force error stops the force until the
    button is pressed anew; a button held since before the error is no new press. Pressed
    with the stylus still in, then a stall's zero, then the contact's full force: the force
    comes back as a ramp, not a step."""
    dev, emu = stopped_by_a_force_error(
        hd_arm, hand_x=-4.0, force=(1.0, 0.0, 0.0), stylus_x=-2.0, buttons=HD_DEVICE_BUTTON_1
    )  # held all along
    assert command_at(dev, emu, -4.0, (1.0, 0.0, 0.0)) == (
        0.0,
        0.0,
        0.0,
    )  # the held button is no new press
    emu.control.buttons = 0
    emu.wait_frames(3)
    emu.control.buttons = HD_DEVICE_BUTTON_1  # pressed again, the stylus still in
    emu.wait_frames(3)
    dev.zero_force_now()  # the loop stalls ...
    emu.wait_frames(20)
    emu.control.max_step = 0.0
    dev.write_force((1.0, 0.0, 0.0))  # ... and comes back pushing
    wait_for_force(emu, (1.0, 0.0, 0.0))
    assert 0.0 < emu.control.max_step <= 0.01  # N per servo frame: no kick
    assert dev.info.details["force_stopped"] is False


# A sloped wall of the daemon's (device frame): free space where p·n > 0, pushing along its
# normal n, which lies 75° from the x axis the hand approaches and withdraws along.
SLOPE = math.radians(75.0)
NORMAL = np.array([math.cos(SLOPE), math.sin(SLOPE), 0.0])
WALL_N_PER_MM = 0.4


def wall_force(tip_mm):
    depth = -float(np.asarray(tip_mm) @ NORMAL)
    return tuple(WALL_N_PER_MM * depth * NORMAL) if depth > 0.0 else (0.0, 0.0, 0.0)


def daemon_ticks_along(dev, emu, xs):
    """The hand moves along x through `xs` (device frame, mm); at each place one daemon tick:
    read the stylus where the hand and the rendered force hold it, write the wall's force for
    that reading. Returns the last force written."""
    force = (0.0, 0.0, 0.0)
    for x in xs:
        emu.hand.target = held_at(x)
        emu.wait_frames(3)
        force = wall_force(dev.read().position_mm)
        dev.write_force(force)
    emu.wait_frames(3)
    return force


def test_force_comes_back_after_leaving_a_sloped_contact_back_along_the_approach(hd_arm):
    """The force at the error points 75° away from the hand's approach; the hand withdraws
    along the approach to just outside the wall (0.26 mm along its normal), where the daemon
    asks for exactly no force, then presses again: the arm renders the daemon's force,
    ramped in."""
    dev, emu = hd_arm(styles=HD_CALIBRATION_AUTO, hand=held_at(1.0))
    dev.open()
    read_until(dev, lambda s: s.calibrated)
    pressing = np.arange(1.0, -10.01, -0.5)
    pressed = daemon_ticks_along(dev, emu, pressing)
    assert np.linalg.norm(pressed) > 0.3 and emu.applied_force == pytest.approx(pressed)
    emu.inject(HD_EXCEEDED_MAX_FORCE)
    emu.wait_frames(5)
    assert emu.applied_force == (0.0, 0.0, 0.0) and dev.info.details["force_stopped"] is True
    assert np.linalg.norm(daemon_ticks_along(dev, emu, [-10.0] * 3)) > 0.0  # still pressed in
    assert emu.applied_force == (0.0, 0.0, 0.0)

    out = daemon_ticks_along(dev, emu, pressing[::-1])  # back along the approach, then held
    assert out == (0.0, 0.0, 0.0) and float(dev.read().position_mm @ NORMAL) < 0.3
    assert dev.info.details["force_stopped"] is False

    emu.control.max_step = 0.0
    again = daemon_ticks_along(dev, emu, pressing)  # pressed again: the daemon's force, ramped
    assert np.linalg.norm(again) > 0.3
    wait_for_force(emu, again)
    assert 0.0 < emu.control.max_step <= 0.01  # N per servo frame: no kick
