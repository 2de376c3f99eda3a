"""The loop's rate: what each device declares, the daemon's refusal of a rate beyond it,
and publishing decimated above 1 kHz while the recording keeps every tick."""

from __future__ import annotations

import pytest
from sasprobe.daemon.loop import pose_stride
from sasprobe.daemon.recording.verify import verify_recording
from sasprobe.daemon.service import Daemon, DaemonConfig
from sasprobe.devices.registry import open_device
from sasprobe.protocol.client import Subscriber

from tests.conftest import run_cli
from tests.support.recordings import reference_ticks

# The rates each driver declares before it opens (none of these opens anything).
DECLARED = {
    "sim": (1000.0, 4000.0),
    "forcedimension": (1000.0, 4000.0),
    "inverse3:ws://127.0.0.1:9": (1000.0, 4000.0),
    "openhaptics": (1000.0, 1000.0),
    "falcon": (1000.0, 1000.0),
    "woodenhaptics:/dev/null": (1000.0, 1000.0),
    "haply:/dev/null": (1000.0, 1000.0),
    "spacemouse": (1000.0, 1000.0),
}


@pytest.mark.parametrize("spec", sorted(DECLARED))
def test_each_device_declares_its_default_and_its_fastest_rate(spec):
    limits = open_device(spec, rate_hz=None).info.limits
    assert (limits.nominal_rate_hz, limits.max_rate_hz) == DECLARED[spec]


@pytest.mark.parametrize(
    "args, fastest",
    [(["--rate", "4001"], "4000"), (["--device", "openhaptics", "--rate", "2000"], "1000")],
)
def test_a_rate_beyond_the_devices_fastest_is_refused_in_one_line(args, fastest):
    result = run_cli("daemon", *args, "--seconds", "1")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert "--rate" in lines[0] and f"at most {fastest} Hz" in lines[0]


def test_poses_go_out_at_a_kilohertz_or_more_whatever_the_rate():
    assert [pose_stride(r) for r in (None, 250, 1000, 1999, 2000, 2999, 3000, 4000)] == [
        1,
        1,
        1,
        1,
        2,
        2,
        3,
        4,
    ]


def test_at_4_khz_every_4th_pose_is_published_and_every_tick_recorded(tmp_path):
    path = tmp_path / "fast.mcap"
    config = DaemonConfig(
        device="sim",
        rate_hz=4000.0,
        pub=[f"ipc://{tmp_path}/p"],
        ctl=[f"ipc://{tmp_path}/c"],
        record=str(path),
        max_seconds=1.0,
    )
    daemon = Daemon(config)
    publisher = daemon.publisher  # the daemon lets go of it when it stops
    subscriber = Subscriber(publisher.endpoints[0])
    try:
        assert daemon.scene["pose_every"] == 4 and daemon.rate_hz == 4000.0
        daemon.run()
        received = subscriber.poll(1.0)
    finally:
        subscriber.close()
    ticks = daemon.loop.stats.total_ticks
    published = publisher.poses_sent + publisher.send_failures
    assert published == (ticks + 3) // 4  # ticks 0, 4, 8, ...
    assert received and all(p.seq % 4 == 0 for p in received)
    recorded = [t["pose"]["seq"] for t in reference_ticks(path)]  # as the README lays it out
    assert recorded == list(range(ticks))
    report = verify_recording(path)  # and the 4 kHz session replays to the same forces
    assert report.ticks == ticks and report.missing_ticks == 0 and report.ok
