"""`sasprobe daemon --help`, `demo --help` and `devices --help` list every --device scheme of
the registry, the daemon's `replay` among them, each with its summary and example (each
help in a fresh process, as a user starts it, so nothing this test process imported
registers a scheme for it)."""

from __future__ import annotations

import os

import pytest
from sasprobe.daemon.recording.replay_scheme import REPLAY_SCHEME
from sasprobe.devices.registry import SCHEMES

from tests.conftest import run_cli


@pytest.mark.parametrize("command", ["daemon", "demo", "devices"])
def test_help_lists_every_device_scheme(command):
    result = run_cli(
        command, "--help", env=dict(os.environ, COLUMNS="70")
    )  # narrow: summaries wrap, and must survive it
    assert result.returncode == 0, result.stderr
    text = " ".join(result.stdout.split())
    schemes = {**SCHEMES, "replay": REPLAY_SCHEME}
    assert {"sim", "replay", "falcon", "openhaptics"} <= set(schemes)
    for name, scheme in schemes.items():
        assert f" {name} {scheme.summary} --device {scheme.example} " in text + " ", name
