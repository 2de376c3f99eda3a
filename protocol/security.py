"""CURVE encryption and client allow-lists (pyzmq's `zmq.auth`).

A key folder made by `sasprobe keys DIR` holds:

    server.key, server.key_secret     the daemon's key pair
    client.key, client.key_secret     a client key pair (more with --client NAME)
    allowed_clients/*.key             public keys of the clients the daemon accepts

The daemon needs `server.key_secret` and `allowed_clients/`; a client needs its own
`NAME.key_secret` and the daemon's `server.key` (public). Keys are Z85 text in
ZeroMQ's certificate format, so clients in other languages can read them too.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from sasprobe.errors import UserError

SERVER_NAME = "server"
DEFAULT_CLIENT_NAME = "client"
ALLOWED_DIR = "allowed_clients"


class KeyFileError(UserError):
    """Missing or unreadable key files."""


@dataclass(frozen=True)
class ServerKeys:
    public: bytes
    secret: bytes
    allowed_dir: Path  # public keys of accepted clients


@dataclass(frozen=True)
class ClientKeys:
    public: bytes
    secret: bytes
    server_public: bytes


def generate_keys(directory: Path, clients: tuple[str, ...] = (DEFAULT_CLIENT_NAME,)) -> list[Path]:
    """Create the server pair (unless present) and one allowed pair per client name; return new files."""
    import zmq.auth

    directory = Path(directory)
    allowed = directory / ALLOWED_DIR
    allowed.mkdir(parents=True, exist_ok=True)
    created: list[Path] = []
    for name in (SERVER_NAME, *clients):
        if not name or "/" in name or name.startswith("."):
            raise UserError(f"key name '{name}' is not a plain file name")
        public = directory / f"{name}.key"
        if public.exists():
            if name != SERVER_NAME:
                raise UserError(f"{public} already exists; choose another client name")
            continue
        public_file, secret_file = zmq.auth.create_certificates(str(directory), name)
        os.chmod(secret_file, 0o600)  # the secret half never leaves this folder readable to others
        created += [Path(public_file), Path(secret_file)]
        if name != SERVER_NAME:
            shutil.copy(public_file, allowed / f"{name}.key")
            created.append(allowed / f"{name}.key")
    return created


def _load(path: Path, need_secret: bool) -> tuple[bytes, bytes | None]:
    import zmq.auth

    if not path.is_file():
        raise KeyFileError(f"{path}: no such key file (create keys with `sasprobe keys DIR`)")
    try:
        public, secret = zmq.auth.load_certificate(str(path))
    except (OSError, ValueError) as exc:
        raise KeyFileError(f"{path}: not a ZeroMQ certificate ({exc})") from None
    if need_secret and not secret:
        raise KeyFileError(f"{path}: holds no secret key")
    return public, secret


def load_server_keys(directory: Path) -> ServerKeys:
    directory = Path(directory)
    public, secret = _load(directory / f"{SERVER_NAME}.key_secret", need_secret=True)
    allowed = directory / ALLOWED_DIR
    if not allowed.is_dir():
        raise KeyFileError(f"{allowed}: no allow-list folder (create keys with `sasprobe keys DIR`)")
    return ServerKeys(public=public, secret=secret or b"", allowed_dir=allowed)


def load_client_keys(directory: Path, name: str = DEFAULT_CLIENT_NAME) -> ClientKeys:
    directory = Path(directory)
    public, secret = _load(directory / f"{name}.key_secret", need_secret=True)
    server_public, _ = _load(directory / f"{SERVER_NAME}.key", need_secret=False)
    return ClientKeys(public=public, secret=secret or b"", server_public=server_public)


def start_authenticator(context, keys: ServerKeys):
    """A ZAP handler thread that accepts CURVE clients whose public key is in the allow-list."""
    from zmq.auth.thread import ThreadAuthenticator

    auth = ThreadAuthenticator(context)
    auth.start()
    auth.configure_curve(domain="*", location=str(keys.allowed_dir))
    return auth


def make_curve_server(socket, keys: ServerKeys) -> None:
    socket.curve_secretkey = keys.secret
    socket.curve_publickey = keys.public
    socket.curve_server = True


def bind_server_socket(socket, endpoints: list[str], keys: ServerKeys | None) -> list[str]:
    """CURVE (when keys) and bind every endpoint; return the bound addresses.

    On failure the socket is closed before the error propagates: an open socket would
    keep Context.term() waiting forever.
    """
    import zmq

    if keys is not None:
        make_curve_server(socket, keys)
    bound = []
    try:
        for endpoint in endpoints:
            socket.bind(endpoint)
            bound.append(socket.getsockopt_string(zmq.LAST_ENDPOINT))
    except zmq.ZMQError:
        socket.close(linger=0)
        raise
    return bound


def make_curve_client(socket, keys: ClientKeys) -> None:
    socket.curve_secretkey = keys.secret
    socket.curve_publickey = keys.public
    socket.curve_serverkey = keys.server_public
