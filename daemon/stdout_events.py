"""What the daemon tells the process that started it: one JSON object a line on stdout.

    {"event": "ready", "pub": [...], "ctl": [...], "device": ..., "rate_hz": ...,
     "pid": ..., "realtime": ...}
    {"event": "stopped", "reason": ..., "ticks": ..., ...}          (the exit report)

Everything else the daemon says goes to stderr. sasprobe/cli/children.py waits for these
events; this module is the one place their names are spelled.
"""

from __future__ import annotations

import json

READY = "ready"  # the loop runs and the sockets are bound: clients may connect
STOPPED = "stopped"  # zero force written, device closed, recording finished: the exit report


def print_event(name: str, **fields) -> None:
    print(json.dumps({"event": name, **fields}), flush=True)
