"""`sasprobe keys DIR`: CURVE key pairs for a daemon that listens beyond loopback."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "create CURVE keys: the daemon's pair and allowed client pairs"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("keys", help=HELP)
    p.add_argument("directory", type=Path, help="folder for the keys (created if missing)")
    p.add_argument(
        "--client",
        action="append",
        metavar="NAME",
        help="name of a client pair to create and allow (repeatable; default 'client')",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.protocol.security import ALLOWED_DIR, DEFAULT_CLIENT_NAME, generate_keys

    clients = tuple(args.client or [DEFAULT_CLIENT_NAME])
    created = generate_keys(args.directory, clients)
    for path in created:
        print(f"created {path}")
    d = args.directory
    print(f"daemon:  sasprobe daemon --keys {d} --pub tcp://0.0.0.0:5555 --ctl tcp://0.0.0.0:5556")
    print(
        f"clients: copy {d}/server.key and {d}/NAME.key_secret to the client machine; "
        f"allow more clients by adding their public NAME.key to {d}/{ALLOWED_DIR}/"
    )
    return 0
