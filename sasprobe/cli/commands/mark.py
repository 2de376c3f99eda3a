"""`sasprobe mark [LABEL]`: drop a labelled mark at the probe's position in a running daemon."""

from __future__ import annotations

import argparse
import json


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.cli.daemon_client import add_daemon_options

    p = sub.add_parser(
        "mark", help="drop a labelled mark at the probe's position (a running daemon)"
    )
    p.add_argument("label", nargs="?", default=None, help='what is there (default "mark N")')
    add_daemon_options(p)
    p.add_argument("--json", action="store_true", help="print the daemon's reply as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.cli.daemon_client import connect

    with connect(args) as client:
        reply = client.mark(args.label)
    mark = reply["mark"]
    if args.json:
        print(json.dumps(reply))
    else:
        x, y, z = mark["position_A"]
        print(
            f"mark {mark['id']} '{mark['label']}' at ({x:.2f}, "
            f"{y:.2f}, {z:.2f}) Å, tick {mark['seq']}"
        )
    return 0
