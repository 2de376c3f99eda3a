"""What a daemon is started with (DaemonConfig, from `sasprobe daemon`'s options), the check
that keeps it on this machine unless it has CURVE keys, and which keys each socket uses."""

from __future__ import annotations

from dataclasses import dataclass, field

from sasprobe.daemon.timer import SPIN_S
from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT, DEFAULT_PUB_ENDPOINT, parse_endpoint
from sasprobe.protocol.security import ServerKeys, ensure_local_keys, load_server_keys

from sasprobe.common.errors import UserError


@dataclass
class DaemonConfig:
    device: str = "sim"
    molecule: str | None = None
    keep_water: bool = False
    # None: the device's nominal rate (a replay: its recorded rate x speed)
    rate_hz: float | None = None
    pub: list[str] = field(default_factory=lambda: [DEFAULT_PUB_ENDPOINT])
    ctl: list[str] = field(default_factory=lambda: [DEFAULT_CTL_ENDPOINT])
    record: str | None = None
    keys: str | None = None
    settings: dict = field(default_factory=dict)  # haptic settings given on the command line
    speed: float | None = 1.0  # replay speed (None: max)
    seed: int = 0
    spin_s: float = SPIN_S
    report: str | None = None  # write a JSON exit report here
    max_seconds: float | None = None  # stop by itself after this long (benchmarks, demos)
    # ask for SCHED_FIFO for the loop and ZeroMQ's I/O thread (fall back with a warning)
    realtime: bool = True
    # simulated-arm fault injection, e.g. "nan@900+5"
    faults: list[str] = field(default_factory=list)
    buttons: list[str] = field(default_factory=list)  # --button ACTION=N (daemon/buttons.py)
    # simulated arm: "BUTTON@TICK+COUNT" held down
    button_presses: list[str] = field(default_factory=list)
    # the scene's colour scheme (None: each renderer's default by structure)
    color_scheme: str | None = None
    load_dir: str | None = None  # `load` may read files below this folder (None: bytes only)
    record_dir: str | None = None  # `record_start` writes below this folder (None: refused)
    # test hook: (tick, seconds) the loop sleeps
    loop_stalls: list[tuple[int, float]] = field(default_factory=list)
    # test hook: (tick, count) reads made slow
    slow_reads: list[tuple[int, int]] = field(default_factory=list)


def check_config(config: DaemonConfig) -> DaemonConfig:
    """What can be checked before anything opens: binds, folders, a new recording file."""
    from pathlib import Path

    from sasprobe.daemon.access import check_folder

    check_bind_security(config.pub + config.ctl, config.keys)
    config.load_dir = check_folder(config.load_dir, "--load-dir")
    config.record_dir = check_folder(config.record_dir, "--record-dir")
    if config.record and Path(config.record).exists():
        raise UserError(f"{config.record}: already exists; record to a new file")
    return config


def check_bind_security(endpoints: list[str], keys_dir: str | None) -> None:
    """Refuse to expose the daemon beyond this machine without CURVE keys."""
    for text in endpoints:
        endpoint = parse_endpoint(text)
        if not endpoint.is_loopback and keys_dir is None:
            raise UserError(
                f"refusing to bind {text} without encryption: an address other machines can reach "
                "needs --keys DIR (CURVE keys with a client allow-list; create them with "
                "`sasprobe keys DIR`)"
            )


def socket_keys(endpoints: list[str], keys_dir: str | None) -> ServerKeys | None:
    """The CURVE keys of a socket: the given folder's; else, when it binds TCP (loopback: every
    user of the machine can reach it), this user's local keys; else (ipc:// only, guarded by
    file permissions) none."""
    from pathlib import Path

    if keys_dir:
        return load_server_keys(Path(keys_dir))
    if any(parse_endpoint(text).transport == "tcp" for text in endpoints):
        return load_server_keys(ensure_local_keys())
    return None
