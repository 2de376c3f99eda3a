"""Opening a file a user named: regular files only, with one clear line for anything else.

A FIFO would block its reader for good, a device such as /dev/zero never ends, and a
folder is not a file. Each is refused on the open descriptor: opened non-blocking (a
FIFO cannot block the open) and checked after opening (nothing can be swapped in
between), with one line naming the file. Every layer may use this (it imports only the
one-line error).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import BinaryIO

from sasprobe.common.errors import UserError

_KINDS = {
    stat.S_IFDIR: "a directory",
    stat.S_IFIFO: "a FIFO",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFSOCK: "a socket",
}


def open_regular(
    path: str | Path, what: str = "file", error: type[UserError] = UserError
) -> BinaryIO:
    """A binary reader of a regular file, or `error` in one line (missing, unreadable, not a
    file)."""
    label = str(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC)
    except FileNotFoundError:
        raise error(f"{label}: no such file") from None
    except OSError as exc:
        raise error(f"{label}: cannot read ({exc.strerror or exc})") from None
    try:
        kind = stat.S_IFMT(os.fstat(fd).st_mode)
        if kind != stat.S_IFREG:
            raise error(f"{label}: is {_KINDS.get(kind, 'not a regular file')}, not a {what}")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(
    path: str | Path, limit: int, what: str = "file", error: type[UserError] = UserError
) -> bytes:
    """The bytes of a regular file of at most `limit` bytes, or `error` in one line."""
    with open_regular(path, what, error) as handle:
        try:
            size = os.fstat(handle.fileno()).st_size
            if size > limit:
                raise error(
                    f"{path}: {size} bytes is larger than the {limit >> 20} MiB a {what} may have"
                )
            data = handle.read(limit + 1)
        except OSError as exc:
            raise error(f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(data) > limit:
        raise error(f"{path}: larger than the {limit >> 20} MiB a {what} may have")
    return data
