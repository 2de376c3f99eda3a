"""Recordings mangled by the thousand: a real session of the simulated arm (an injected fault
and a control change in it), cut anywhere, with bytes flipped or inserted, a stretch of the
file repeated or dropped, or spliced onto another. Each one gives a result or one line:
through the reader (summary, the records, --recover), the replay device a daemon runs
(`--device replay:FILE`: every read answers, then the end), and `sasprobe replay --verify`
in this process (a traceback is this test's failure). tests/support/fuzz.py says how many.

The schema checks tests/conftest.py puts on the reader are lifted here: a mangled file's
records are the reader's to refuse, not the protocol's to validate."""

from __future__ import annotations

import io
import json
import logging
import time
from contextlib import redirect_stderr, redirect_stdout

import pytest
from hypothesis import given
from hypothesis import strategies as st
from sasprobe.daemon.recording.replay import ReplayFinished, open_replay, open_session
from sasprobe.devices.base import DeviceFault
from sasprobe.protocol import recording
from sasprobe.protocol.client import ControlClient
from sasprobe.protocol.ticks import TickBlock

from sasprobe.cli.main import main
from sasprobe.common.errors import UserError
from tests.support.daemon_process import DaemonProcess
from tests.support.fuzz import Seeds, cli_error_lines, fuzz_settings, one_line_error


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    """Two real recordings: one with a fault and a change of stiffness, and a plain one."""
    folder = tmp_path_factory.mktemp("seeds")
    out = Seeds()
    for name, args in (("faulted", ["--inject-fault", "raise@150+20"]), ("plain", [])):
        path = folder / f"{name}.mcap"
        with DaemonProcess("--record", str(path), *args) as d:
            with ControlClient(d.ctl, timeout_s=30) as client:
                deadline = time.monotonic() + 120
                while client.status()["loop"]["total"]["ticks"] < 300:
                    assert time.monotonic() < deadline, "the daemon did not tick"
                    time.sleep(0.05)
                client.set(stiffness_n_per_mm=0.25)
                time.sleep(0.2)
            assert d.stop()[0] == 0, d.stderr
        out.append(path.read_bytes())
    return out


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("mangled")


@pytest.fixture
def unchecked_reader(monkeypatch):
    """The reader without the schema checks of tests/support/schema_check.py (a mangled file
    is what they would refuse)."""
    checked = recording.Recording.items
    monkeypatch.setattr(recording.Recording, "items", getattr(checked, "__wrapped__", checked))


@pytest.fixture
def cli_logging_restored():
    logger = logging.getLogger("sasprobe")
    saved = logger.handlers[:], logger.level, logger.propagate
    yield
    logger.handlers[:], logger.level, logger.propagate = saved


def mangle(seeds: list[bytes], draw) -> bytes:
    data = seeds[draw(st.integers(0, len(seeds) - 1))]  # (an index: draws are printed)
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(data)))
        kind = draw(st.sampled_from(["cut", "flip", "insert", "repeat", "drop", "splice"]))
        if kind == "cut":
            data = data[:at]
        elif kind == "flip" and at < len(data):
            data = data[:at] + bytes([data[at] ^ draw(st.integers(1, 255))]) + data[at + 1 :]
        elif kind == "insert":
            data = data[:at] + draw(st.binary(min_size=1, max_size=64)) + data[at:]
        elif kind in ("repeat", "drop"):
            end = min(len(data), at + draw(st.integers(1, 4096)))
            data = data[:end] + data[at:] if kind == "repeat" else data[:at] + data[end:]
        elif kind == "splice":
            other = seeds[draw(st.integers(0, len(seeds) - 1))]
            data = data[:at] + other[draw(st.integers(0, len(other))) :]
    return data


@fuzz_settings(150)
@given(data=st.data())
def test_a_mangled_recording_reads_or_is_refused_in_one_line(seeds, folder, unchecked_reader, data):
    path = folder / "mangled.mcap"
    path.write_bytes(mangle(seeds, data.draw))
    try:
        summary = recording.summarize(path)
        streamed = recording.Recording(path).stream()
        ticks = sum(len(item) for item in streamed if isinstance(item, TickBlock))
        assert ticks == summary.ticks
        recovered = recording.recover(path, folder / "recovered.mcap")
        assert recovered.finished and recovered.ticks == summary.ticks
    except UserError as exc:
        one_line_error(exc)
    finally:
        (folder / "recovered.mcap").unlink(missing_ok=True)
    try:
        device = open_replay(str(path), speed=None)
    except UserError as exc:
        one_line_error(exc)
        return
    device.open()
    try:
        for _ in range(10**6):  # the daemon's loop: every read answers, until the end
            try:
                device.read()
            except ReplayFinished:
                return
            except DeviceFault as exc:
                one_line_error(exc)
            device.take_recorded_events()
            device.write_force(device.last_force_n)
        raise AssertionError("the replay never came to its end")
    finally:
        device.close()


def test_damaged_device_limits_are_refused_in_one_line(seeds, folder):
    """Found by the fuzz below: a byte flipped in the compressed start record renamed a limit,
    and --verify ended in a KeyError."""
    path = folder / "limits.mcap"
    path.write_bytes(seeds[0])
    session = open_session(path)
    del session.start["device"]["limits"]["workspace_min_mm"]
    with pytest.raises(UserError) as refused:
        session.device_limits()
    assert "the start record's device limits are damaged" in one_line_error(refused.value)


@fuzz_settings(40)
@given(data=st.data())
def test_replay_verify_on_a_mangled_recording_answers_or_says_why_in_one_line(
    seeds, folder, unchecked_reader, cli_logging_restored, data
):
    path = folder / "verified.mcap"
    path.write_bytes(mangle(seeds, data.draw))
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        status = main(["replay", str(path), "--verify", "--json"])
    assert status in (0, 1, 2)  # verified, forces differ (a spliced session), refused
    cli_error_lines(err.getvalue(), failed=status == 2)
    if status != 2:
        assert json.loads(out.getvalue())["verify"]["ok"] == (status == 0)
