"""The window path under a real X server (Xvfb, conftest.py's `xvfb`): the window opens,
shows the molecule (an X-level screenshot of the root window, independent of GL), and its
own screenshot (--out) matches what the X server shows."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import imageio.v3 as iio
import numpy as np

from tests.conftest import REPO_ROOT, run_window_check
from tests.support.bounded import lines_until
from tests.support.window import x_screenshot

WINDOW = (320, 240)
BACKGROUND = np.array([20, 23, 28])  # ShadingSettings.background * 255


def _start_window(display: str, *args: str) -> subprocess.Popen:
    env = dict(os.environ, DISPLAY=display, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "sasprobe",
            "-v",
            "render",
            "--size",
            f"{WINDOW[0]}x{WINDOW[1]}",
            *args,
        ],
        cwd=REPO_ROOT,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines = lines_until(proc.stderr, lambda line: "window open" in line, 90.0)
    assert any("window open" in seen for seen in lines), (
        f"no window (exit {proc.poll()}): {''.join(lines)}"
    )
    return proc


def test_window_opens_and_shows_the_molecule(xvfb, tmp_path):
    shot = tmp_path / "shot.png"
    proc = _start_window(xvfb, "--seconds", "120", "--out", str(shot))
    try:
        # Frames are being presented; let a few reach the X server.
        for _ in range(60):
            time.sleep(1.0)
            screen = x_screenshot(xvfb)
            painted = np.any(screen != 0, axis=2)
            if painted.sum() >= 0.9 * WINDOW[0] * WINDOW[1] and _molecule_pixels(screen) > 500:
                break
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    ys, xs = np.nonzero(painted)
    assert (ys.max() - ys.min() + 1, xs.max() - xs.min() + 1) == (WINDOW[1], WINDOW[0]), (
        "the window is not on screen at its size"
    )
    window = screen[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1]
    assert (np.abs(window.astype(int) - BACKGROUND).max(axis=2) <= 2).mean() > 0.2, (
        "no background around the molecule"
    )
    assert _molecule_pixels(window) > 500, "the X server shows no CPK-coloured atoms"
    # The app's own screenshot (read from the window's framebuffer) shows the same picture
    # (the overlay's text and fps figures in the top-left corner aside).
    own = iio.imread(shot)[..., :3]
    assert own.shape == window.shape
    same = np.abs(own.astype(int) - window.astype(int)).max(axis=2) <= 3
    same[:80, :200] = True
    assert same.mean() > 0.98


def _molecule_pixels(rgb: np.ndarray) -> int:
    """Pixels of shaded CPK oxygen (red) or carbon (grey) atoms."""
    r, g, b = (rgb[..., i].astype(int) for i in range(3))
    oxygen = (r > 90) & (g < r // 3) & (b < r // 3)
    carbon = (r > 70) & (np.abs(r - g) < 12) & (np.abs(r - b) < 12)
    return int(np.count_nonzero(oxygen | carbon))


def _window_region(display: str) -> tuple[slice, slice]:
    for _ in range(30):
        painted = np.any(x_screenshot(display) != 0, axis=2)
        if painted.sum() >= 0.9 * WINDOW[0] * WINDOW[1]:
            ys, xs = np.nonzero(painted)
            return slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1)
        time.sleep(1.0)
    raise AssertionError("the window never appeared on the X screen")


def test_window_waits_for_the_daemon_and_survives_it_going_away(xvfb):
    """No daemon: the window opens and waits (no molecule). A daemon starts: the molecule
    appears. It stops: the window stays up. It comes back: the picture moves again."""
    from tests.support.daemon_process import DaemonProcess, free_tcp_endpoint

    pub, ctl = free_tcp_endpoint(), free_tcp_endpoint()

    def start_daemon() -> DaemonProcess:
        return DaemonProcess("--seconds", "600", device="sim:orbit", pub=pub, ctl=ctl)

    proc = _start_window(
        xvfb, "--connect", pub, "--control", ctl, "--probe-plane", "--seconds", "600"
    )
    daemon = None
    try:
        rows, cols = _window_region(xvfb)
        below_text = lambda: x_screenshot(xvfb)[rows, cols][100:]  # noqa: E731 (under the readout)
        time.sleep(2.0)
        assert _molecule_pixels(below_text()) < 30, "nothing to draw before the daemon is there"
        daemon = start_daemon()
        deadline = time.monotonic() + 90
        while _molecule_pixels(below_text()) < 300 and time.monotonic() < deadline:
            time.sleep(1.0)
        assert _molecule_pixels(below_text()) >= 300, (
            "the molecule did not appear once the daemon ran"
        )
        daemon.stop(signal.SIGINT)
        time.sleep(3.0)
        frozen = below_text()
        time.sleep(2.0)
        assert proc.poll() is None, "the window must survive the daemon going away"
        assert np.array_equal(frozen, below_text()), "no poses: the picture holds still"
        daemon = start_daemon()
        deadline = time.monotonic() + 60
        moved = False
        while not moved and time.monotonic() < deadline:
            time.sleep(1.0)
            moved = np.abs(below_text().astype(int) - frozen.astype(int)).max() > 30
        assert moved, "the probe should move again once the daemon is back"
        assert proc.poll() is None
    finally:
        if daemon is not None:
            daemon.stop(signal.SIGINT)
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err


def test_the_help_is_whole_the_overview_fills_the_picture_and_a_waiting_window_shows_the_arm(xvfb):
    """H's help panel fits the window with every line drawn; Tab's overview frames the
    molecule, its cube and trace across the picture; before a daemon's structure arrives
    the window shows the cube and the probe under its progress line
    (tests/window_scripts/render_layout.py, read from the window's screenshots)."""
    run_window_check(xvfb, "tests.window_scripts.render_layout")


def test_every_render_key_and_the_mouse_change_the_picture(xvfb):
    """F B N W P L D T K X O each flip their switch and change the picture, pressed again
    they restore it exactly; M swaps quads for sprites, H shows the help, a drag turns,
    the wheel zooms, R resets the camera, Q closes (tests/window_scripts/render_keys.py)."""
    run_window_check(xvfb, "tests.window_scripts.render_keys")


def test_click_names_the_atom_and_capture_keys_write_what_the_window_shows(xvfb):
    """A click names the atom a numpy ray cast finds under the cursor (with its SAS area),
    Ctrl+S writes a PNG equal to the X server's copy of the window, Ctrl+R a video, the
    wheel zooms about the cursor's point, C and I recolour and relight, Z centres on the
    probe (tests/window_scripts/render_pick.py)."""
    run_window_check(xvfb, "tests.window_scripts.render_pick")
