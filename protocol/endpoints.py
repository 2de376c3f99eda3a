"""Default endpoints and the rules for which addresses the daemon may bind.

Endpoints are ZeroMQ addresses: `tcp://HOST:PORT` or `ipc://PATH`. The daemon binds
loopback by default; any other TCP address (a LAN address, `*`, `0.0.0.0`, a host or
interface name) is reachable from other machines and needs CURVE keys (see security.py).
ipc:// endpoints are local sockets guarded by file permissions (the daemon creates them
0600) and need no keys; binding one never replaces a file or a live socket.
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import os
import socket
import stat
from dataclasses import dataclass

from sasprobe.common.errors import UserError

DEFAULT_PUB_ENDPOINT = "tcp://127.0.0.1:5555"  # PUB: pose and scene
DEFAULT_CTL_ENDPOINT = "tcp://127.0.0.1:5556"  # control requests and replies

_LOOPBACK_NAMES = {"localhost", "ip6-localhost", "ip6-loopback"}


class EndpointError(UserError):
    """An endpoint string the daemon cannot use."""


@dataclass(frozen=True)
class Endpoint:
    text: str  # as given, e.g. "tcp://127.0.0.1:5555"
    transport: str  # "tcp" | "ipc"
    host: str = ""  # tcp only, without IPv6 brackets
    port: str = ""  # tcp only: a number, or "*" for any free port
    path: str = ""  # ipc only

    @property
    def is_loopback(self) -> bool:
        """True when only processes on this machine can reach the endpoint."""
        if self.transport == "ipc":
            return True
        if self.host.lower() in _LOOPBACK_NAMES:
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:  # "*", a host name or an interface name: not provably local
            return False


def parse_endpoint(text: str) -> Endpoint:
    """Validate `tcp://HOST:PORT` or `ipc://PATH`; EndpointError with one clear line otherwise."""
    transport, sep, rest = text.partition("://")
    if not sep or not rest:
        raise EndpointError(f"endpoint '{text}' is not tcp://HOST:PORT or ipc://PATH")
    transport = transport.lower()
    if transport == "ipc":
        return Endpoint(text=text, transport="ipc", path=rest)
    if transport != "tcp":
        raise EndpointError(
            f"endpoint '{text}': transport '{transport}' is not supported (use tcp:// or ipc://)"
        )
    host, colon, port = rest.rpartition(":")
    if not colon or not host:
        raise EndpointError(f"endpoint '{text}' lacks a port (tcp://HOST:PORT)")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if port != "*":
        if not port.isdigit() or not 1 <= int(port) <= 65535:
            raise EndpointError(f"endpoint '{text}': port '{port}' is not a number from 1 to 65535")
    return Endpoint(text=text, transport="tcp", host=host, port=port)


@contextlib.contextmanager
def socket_file_umask():
    """umask 177 for the duration, so a socket file is made 0600: read and write (connecting
    needs write) for its owner, nothing for anyone else, no execute bit. Process-wide, so
    only around a bind at start-up."""
    old = os.umask(0o177)
    try:
        yield
    finally:
        os.umask(old)


def check_ipc_path(path: str) -> None:
    """Refuse to bind an ipc:// path that holds anything but a dead socket.

    libzmq unlinks whatever is at the path before binding: a regular file would be lost,
    and a live socket would be stolen from the daemon that serves it."""
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise EndpointError(f"ipc://{path}: cannot use this path ({exc.strerror or exc})") from None
    if not stat.S_ISSOCK(info.st_mode):
        raise EndpointError(
            f"ipc://{path}: the path exists and is not a socket; refusing to replace it"
        )
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        probe.connect(path)
    except OSError as exc:
        if exc.errno in (errno.ECONNREFUSED, errno.ENOENT):
            return  # a socket left behind by a daemon that is gone
        raise EndpointError(f"ipc://{path}: cannot use this path ({exc.strerror or exc})") from None
    finally:
        probe.close()
    raise EndpointError(f"ipc://{path}: another process is listening there (another daemon?)")


def socket_files(bound: list[str]) -> dict[str, tuple[int, int]]:
    """The socket files of bound ipc:// endpoints and their identity (device, inode), taken
    right after binding so that `remove_socket_files` removes only these."""
    files = {}
    for endpoint in bound:
        parsed = parse_endpoint(endpoint)
        if parsed.transport == "ipc":
            with contextlib.suppress(OSError):
                info = os.lstat(parsed.path)
                files[parsed.path] = (info.st_dev, info.st_ino)
    return files


def remove_socket_files(files: dict[str, tuple[int, int]]) -> None:
    """Remove socket files once their socket is closed (libzmq leaves them), unless the path
    holds something else by now."""
    for path, identity in files.items():
        with contextlib.suppress(OSError):
            info = os.lstat(path)
            if stat.S_ISSOCK(info.st_mode) and (info.st_dev, info.st_ino) == identity:
                os.unlink(path)
