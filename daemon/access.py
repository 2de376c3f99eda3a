"""What a client may make the daemon touch on its disk: only what lies below the folders the
daemon was started with.

Control clients are other processes, possibly another user's or another machine's, and
the daemon may run as root; so `load` takes a structure's bytes, and reads a path only
below `--load-dir`, and `record_start` creates a new file only below `--record-dir`.
Paths are resolved (symlinks followed) before the check, and the refusal of a path
outside says nothing about whether it exists.
"""

from __future__ import annotations

import os
from pathlib import Path

from sasprobe.common.errors import UserError


def check_folder(path: str | None, flag: str) -> str | None:
    """At start-up: the folder of --load-dir / --record-dir must exist (None stays None)."""
    if path is None:
        return None
    if not Path(path).is_dir():
        raise UserError(f"{flag} {path}: no such folder")
    return os.path.realpath(path)


def path_below(root: str | None, requested: str, flag: str, what: str) -> Path:
    """`requested` (relative to root, or absolute) resolved; UserError unless it lies below root."""
    if root is None:
        raise UserError(
            f"this daemon takes no paths for {what}; start it with {flag} DIR to allow a folder"
        )
    base = Path(root)
    resolved = Path(os.path.realpath(base / requested))
    if resolved == base or not resolved.is_relative_to(base):
        raise UserError(f"'{requested[:200]}' is not below the daemon's {flag} folder")
    return resolved
