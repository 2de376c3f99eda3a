"""Shared by the web tests: headless Chromium (or a skip, a failure under CI=true, where it is
missing), `sasprobe web` following a test daemon, and reading what a page picked."""

from __future__ import annotations

import base64
import contextlib
import time

import numpy as np

from tests.conftest import skip_or_fail


def browser(**options):
    """A headless Chromium (sasprobe.cli.browser.Browser), or a skip naming what is missing."""
    from sasprobe.cli.browser import Browser, find_browser
    from sasprobe.common.errors import UserError

    try:
        find_browser()
    except UserError as exc:
        skip_or_fail(f"no headless browser: {exc}")
    return Browser(**options)


@contextlib.contextmanager
def bridge_for(pub: str, ctl: str, *args: str):
    """`sasprobe web` following the daemon at these endpoints (started or not)."""
    from sasprobe.cli.browser import WebBridge

    bridge = WebBridge("--connect", pub, "--control", ctl, *args)
    try:
        yield bridge
    finally:
        bridge.stop()


def wait_for(condition, timeout_s: float, why: str, every_s: float = 0.05):
    """Poll until `condition()` is true; AssertionError saying `why` after timeout_s."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"{why} (not within {timeout_s:g} s)")
        time.sleep(every_s)


def picked_ids(picked: dict) -> np.ndarray:
    """The id per pixel a page's `pick()` returned, (height, width), row 0 at the top."""
    data = base64.b64decode(picked["ids"])
    return np.frombuffer(data, dtype="<i4").reshape(picked["height"], picked["width"])


def drawing(page, frames: int = 3, timeout_s: float = 120.0) -> dict:
    """Wait until the page has drawn `frames` frames; its state."""
    return page.wait(
        lambda p: (s := p.state()) and s["frames"] >= frames and s,
        timeout_s,
        f"the page draws {frames} frames",
    )
