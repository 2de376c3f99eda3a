"""`python -m sasprobe.daemon.findings RECORDING DIR [--probe-radius R] [--json]`: the findings
as a process of their own (the daemon's `findings` command starts this; daemon/findings_job.py).

It first takes normal scheduling and a lower priority, whatever it inherited, so the
analysis never competes with the daemon's loop. The result is one line on stdout: the
summary as JSON with --json, else the terminal summary; an error is one line too
(`{"error": ...}` with --json) and exit status 2. A daemon that stops while the analysis
runs has closed the pipe the result goes to: the files are written all the same, and
one line on stderr says so.
"""

from __future__ import annotations

import os


def _step_aside() -> None:
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        os.nice(10)
    except (OSError, AttributeError):
        pass


def main() -> int:
    _step_aside()
    import argparse
    import json
    import sys

    from sasprobe.daemon.findings.report import summary_lines, write_findings

    from sasprobe.common.errors import UserError

    p = argparse.ArgumentParser(prog="python -m sasprobe.daemon.findings")
    p.add_argument("recording")
    p.add_argument("dir")
    p.add_argument("--probe-radius", type=float, default=None)
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    try:
        found = write_findings(args.recording, args.dir, args.probe_radius)
    except UserError as exc:
        print(
            json.dumps({"error": str(exc)}) if args.json else str(exc),
            file=sys.stdout if args.json else sys.stderr,
        )
        return 2
    try:
        if args.json:
            print(json.dumps(brief(found)), flush=True)
        else:
            print("\n".join(summary_lines(found)), flush=True)
    except BrokenPipeError:  # the daemon that asked has gone; the files are written
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nothing left to flush
        print(
            f"findings: written into {args.dir} (the daemon that asked has gone)", file=sys.stderr
        )
    return 0


def brief(found: dict) -> dict:
    """What the daemon's `status` shows of a finished analysis (findings.json has the rest)."""
    return {
        "files": found["files"],
        "bottleneck": found["bottleneck"],
        "verdict": found["verdict"],
        "marks": len(found["marks"]),
        "touched_residues": len(found["touched_residues"]),
        "session": found["session"],
        "notes": found["notes"],
    }


if __name__ == "__main__":
    raise SystemExit(main())
