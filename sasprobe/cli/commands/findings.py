"""`sasprobe findings DIR`: what a running daemon's session has found so far, written on its host.

The daemon analyses its own recording up to now (control command `findings`) in a
process of its own; this waits for it (unless --no-wait) and prints the summary.
`sasprobe replay FILE --findings DIR` does the same for a recording file.
"""

from __future__ import annotations

import argparse
import json
import time


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.cli.argtypes import probe_radius
    from sasprobe.cli.daemon_client import add_daemon_options

    p = sub.add_parser(
        "findings",
        help="a running daemon's findings so far (path, residues, marks, bottleneck) "
        "into DIR on its host",
    )
    p.add_argument(
        "dir",
        help="folder on the daemon's host, relative to the daemon's working directory "
        "(made if missing)",
    )
    p.add_argument(
        "--probe-radius",
        type=probe_radius,
        default=None,
        metavar="ANGSTROM",
        help="the probe whose passage the verdict is about (default: the session's)",
    )
    add_daemon_options(p)
    p.add_argument(
        "--no-wait",
        action="store_true",
        help="start the analysis and return (`sasprobe status` tells)",
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=600.0,
        metavar="S",
        help="how long to wait for the analysis",
    )
    p.add_argument("--json", action="store_true", help="print the job as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.cli.daemon_client import connect
    from sasprobe.common.errors import UserError
    from sasprobe.common.progress import progress_bar
    from sasprobe.protocol.client import ControlError

    with connect(args) as client:
        job = client.findings(args.dir, args.probe_radius)
        if not args.no_wait:
            deadline = time.monotonic() + args.timeout
            bar = progress_bar(
                None, desc="findings (daemon)", unit="s", bar_format="{desc}: {elapsed}"
            )
            try:
                while job["state"] == "running" and time.monotonic() < deadline:
                    time.sleep(0.5)
                    bar.update(0.5)
                    job = client.status()["findings"]
            except ControlError as exc:  # the daemon went (or hangs): its analysis goes on
                raise UserError(
                    f"findings: {exc}; the analysis (pid {job['pid']}) still writes "
                    f"{job['dir']}/ on the daemon's host"
                ) from None
            finally:
                bar.close()
    if args.json:
        print(json.dumps(job))
    elif job["state"] == "running":
        print(
            f"findings: analysing {job['recording']} into "
            f"{job['dir']} on the daemon's host (pid {job['pid']})"
        )
    if job["state"] == "failed":
        raise UserError(f"findings: {job['error']}")
    if job["state"] == "done" and not args.json:
        r = job["result"]
        print(
            f"findings  {r['session']['duration_s']:.1f} s so far, {r['touched_residues']} "
            f"residues touched, {r['marks']} marks; {r['verdict']['verdict']}"
        )
        print(f"  files   {job['dir']}/ on the daemon's host: {', '.join(r['files'].values())}")
    return 0 if job["state"] != "running" or args.no_wait else 1
