"""The CLI's way to a running daemon: the `--ctl` and `--keys` options the client commands
(status, set, mark, findings) share, and the control client they open from them."""

from __future__ import annotations

import argparse


def add_daemon_options(parser: argparse.ArgumentParser) -> None:
    from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT

    parser.add_argument(
        "--ctl",
        default=DEFAULT_CTL_ENDPOINT,
        metavar="ENDPOINT",
        help=f"the daemon's control endpoint (default {DEFAULT_CTL_ENDPOINT})",
    )
    parser.add_argument("--keys", metavar="DIR", help="client keys (a daemon with --keys)")


def connect(args: argparse.Namespace, timeout_s: float | None = None):
    """A ControlClient for `--ctl` with the `--keys` client keys (this user's local keys
    when none are given); `timeout_s` per reply, else the client's default."""
    from pathlib import Path

    from sasprobe.protocol.client import ControlClient
    from sasprobe.protocol.security import load_client_keys

    keys = load_client_keys(Path(args.keys)) if args.keys else None
    options = {} if timeout_s is None else {"timeout_s": timeout_s}
    return ControlClient(args.ctl, keys=keys, **options)
