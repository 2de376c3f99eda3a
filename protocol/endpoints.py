"""Default endpoints and the rules for which addresses the daemon may bind.

Endpoints are ZeroMQ addresses: `tcp://HOST:PORT` or `ipc://PATH`. The daemon binds
loopback by default; any other TCP address (a LAN address, `*`, `0.0.0.0`, a host or
interface name) is reachable from other machines and needs CURVE keys (see security.py).
ipc:// endpoints are local sockets guarded by file permissions and need no keys.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

from sasprobe.errors import UserError

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
        raise EndpointError(f"endpoint '{text}': transport '{transport}' is not supported (use tcp:// or ipc://)")
    host, colon, port = rest.rpartition(":")
    if not colon or not host:
        raise EndpointError(f"endpoint '{text}' lacks a port (tcp://HOST:PORT)")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if port != "*":
        if not port.isdigit() or not 1 <= int(port) <= 65535:
            raise EndpointError(f"endpoint '{text}': port '{port}' is not a number from 1 to 65535")
    return Endpoint(text=text, transport="tcp", host=host, port=port)
