"""Headless Chromium through Selenium, as `sasprobe bench web` and the page's tests drive it,
and `sasprobe web` as a child process.

Chromium draws WebGL2 with SwiftShader through ANGLE (`--enable-unsafe-swiftshader
--use-angle=swiftshader`: without the second flag the session page took twenty times
the CPU a frame), on a fresh profile, with everything that would reach the network switched
off (a closed network refuses those connections), with the GPU thread in the browser's
process (`--in-process-gpu`: taking a screenshot needs it here). Chromium's unpaced mode
(`--disable-frame-rate-limit`) is not offered: with SwiftShader the page hands frames to the
GPU process faster than it draws them, and the backlog stalls the page for a minute at a
time; `sasprobe bench web` times finished frames instead. Every wait is bounded: the
driver's page-load and script timeouts, and explicit deadlines here.
"""

from __future__ import annotations

import os
import queue
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path

from sasprobe.cli.children import Child, child_env
from sasprobe.common.errors import UserError

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
DRIVERS = ("chromedriver",)
TIMEOUT_S = 120.0  # the driver's page-load and script timeouts (a loaded machine is slow)
FLAGS = (
    "--headless=new",
    "--enable-unsafe-swiftshader",
    "--use-angle=swiftshader",
    "--no-sandbox",
    "--disable-gpu-sandbox",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-default-apps",
    "--disable-extensions",
    "--no-first-run",
    "--no-default-browser-check",
    "--mute-audio",
    "--in-process-gpu",
)


def find_browser() -> tuple[str, str]:
    """(chromium, chromedriver) paths; UserError naming what is missing."""
    browser = next((p for p in map(shutil.which, BROWSERS) if p), None)
    driver = next((p for p in map(shutil.which, DRIVERS) if p), None)
    try:
        import selenium  # noqa: F401
    except ModuleNotFoundError:
        raise UserError("Selenium is not installed (pip install -e '.[test]')") from None
    if browser is None or driver is None:
        missing = " and ".join(
            n for n, p in (("chromium", browser), ("chromedriver", driver)) if not p
        )
        raise UserError(f"no {missing} (Debian: apt-get install chromium chromium-driver)")
    return browser, driver


class Browser:
    """One headless Chromium with a fresh profile, closed on exit."""

    def __init__(self, size: tuple[int, int] = (1280, 720), flags: tuple = ()) -> None:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        browser, driver = find_browser()
        self.profile = tempfile.mkdtemp(prefix="sasprobe-chromium-")
        options = webdriver.ChromeOptions()
        options.binary_location = browser
        for flag in (*FLAGS, *flags, f"--user-data-dir={self.profile}"):
            options.add_argument(flag)
        options.add_argument(f"--window-size={size[0]},{size[1]}")
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        try:
            self.driver = webdriver.Chrome(service=Service(driver), options=options)
        except Exception as exc:  # noqa: BLE001 - Selenium's errors alike: one line
            shutil.rmtree(self.profile, ignore_errors=True)
            raise UserError(f"Chromium did not start: {str(exc).splitlines()[0]}") from None
        self.driver.set_page_load_timeout(TIMEOUT_S)
        self.driver.set_script_timeout(TIMEOUT_S)
        self.viewport(*size)

    def viewport(self, width: int, height: int) -> None:
        """The page's size in CSS pixels, exactly (one device pixel each)."""
        self.driver.execute_cdp_cmd(
            "Emulation.setDeviceMetricsOverride",
            {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
        )

    def open(self, url: str) -> None:
        self.driver.get(url)

    def run(self, script: str, *args):
        return self.driver.execute_script(script, *args)

    def state(self) -> dict | None:
        return self.run("return window.sasprobe ? window.sasprobe.state() : null")

    def wait(self, what, timeout_s: float, why: str, every_s: float = 0.1):
        """Poll `what(self)` until it returns something true; AssertionError after timeout_s."""
        deadline = time.monotonic() + timeout_s
        while True:
            value = what(self)
            if value:
                return value
            if time.monotonic() > deadline:
                raise AssertionError(f"{why}: not within {timeout_s:g} s (page: {self.state()})")
            time.sleep(every_s)

    def console(self) -> list[str]:
        return [e["message"] for e in self.driver.get_log("browser")]

    def close(self) -> None:
        try:
            self.driver.quit()
        finally:
            shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class WebBridge(Child):
    """`sasprobe web --port 0 ARGS` as a child (sasprobe/cli/children.py: its own process group,
    stopped with its parent), its URL read from its first line of output."""

    def __init__(self, *args: str, ready_s: float = 90.0) -> None:
        self._lines: queue.Queue = queue.Queue()
        self.folder = Path(tempfile.mkdtemp(prefix="sasprobe-web-"))
        super().__init__(
            "web",
            [sys.executable, "-m", "sasprobe", "-v", "web", "--port", "0", *args],
            self.folder / "web.log",
            env=child_env(),
        )
        try:
            line = self._lines.get(timeout=ready_s)
        except queue.Empty:
            line = None
        if not line or not line.startswith("http"):
            why = self.error_line() if not self.alive() else f"no URL within {ready_s:g} s"
            self.stop()
            raise UserError(f"sasprobe web did not start: {why}")
        self.url = line

    def _read_stdout(self) -> None:
        for line in self.proc.stdout:
            self._lines.put(line.decode(errors="replace").strip())
        self._lines.put(None)

    def cpu_s(self) -> float:
        """CPU time (user + system) the bridge has used so far."""
        fields = Path(f"/proc/{self.pid}/stat").read_text().rpartition(")")[2].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def stderr(self) -> str:
        return self.log_path.read_text(errors="replace")

    def stop(self, timeout_s: float = 10.0) -> int:
        self.signal(signal.SIGTERM)
        rc = self.finish(timeout_s)
        shutil.rmtree(self.folder, ignore_errors=True)
        return rc

    def __enter__(self) -> WebBridge:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
