"""The `replay` --device scheme: a session the daemon recorded, played back as a device
(daemon/recording/replay.py). Its device lives above devices/, so the daemon adds the
scheme to the device registry; this module holds only the registry entry, so that
`--help` can list it without loading the replay device."""

from __future__ import annotations

from sasprobe.devices.registry import DeviceScheme, register_scheme

REPLAY_SCHEME = DeviceScheme(
    "sasprobe.daemon.recording.replay:open_replay",
    "a recorded session (--speed X|max)",
    "replay:session.mcap",
)


def register() -> None:
    register_scheme("replay", REPLAY_SCHEME)
