"""The launcher of daemon children (sasprobe/cli/children.py): a daemon that fails is
reported with its own error line, even when its output closes before the process is gone."""

from __future__ import annotations

import sys

import pytest

from sasprobe.cli.children import Child, DaemonChild, child_env
from sasprobe.common.errors import UserError

# stdout closes first, the error line and the exit come later: the order in which a
# failing daemon's end can reach the parent.
FAILING = """
import os, sys, time
os.close(1)
time.sleep(0.5)
sys.stderr.write("sasprobe: error: no such serial port: /dev/ttyUSB9\\n")
sys.exit(2)
"""


class ScriptedDaemon(DaemonChild):
    """DaemonChild's waiting on a stand-in process (what it waits for is the point)."""

    def __init__(self, script: str, log_path) -> None:
        Child.__init__(self, "daemon", [sys.executable, "-c", script], log_path)


def test_a_failing_daemon_is_reported_with_its_own_line(tmp_path):
    daemon = ScriptedDaemon(FAILING, tmp_path / "daemon.log")
    try:
        with pytest.raises(UserError) as caught:
            daemon.wait_ready(90.0)
    finally:
        daemon.finish(10.0)
    assert str(caught.value) == "the daemon did not start: no such serial port: /dev/ttyUSB9"


def test_a_silent_daemon_is_reported_as_silent(tmp_path):
    daemon = ScriptedDaemon("import time; time.sleep(30)", tmp_path / "daemon.log")
    try:
        with pytest.raises(UserError, match="no answer within 0.5 s"):
            daemon.wait_ready(0.5)
    finally:
        daemon.kill_group()
        daemon.finish(10.0)


CRASHING = """
import faulthandler

def draw():
    faulthandler._sigsegv()  # a segmentation fault, as a GL driver's would be

draw()
"""


def test_a_child_that_crashes_is_reported_by_its_fatal_error_and_where(tmp_path):
    """A fault-handler dump ends in the outermost frame (or a list of extension modules): the
    report names the fault and the frame it happened in instead."""
    log = tmp_path / "render.log"
    child = Child("render", [sys.executable, "-c", CRASHING], log, env=child_env())
    assert child.finish(60.0) != 0
    assert log.read_text().splitlines()[-1].strip() == 'File "<string>", line 7 in <module>'
    assert (
        child.error_line() == "Fatal Python error: Segmentation fault at <string>, line 5 in draw"
    )
