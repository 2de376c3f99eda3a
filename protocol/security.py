"""CURVE encryption and client allow-lists (pyzmq's `zmq.auth`).

A key folder made by `sasprobe keys DIR` holds:

    server.key, server.key_secret     the daemon's key pair
    client.key, client.key_secret     a client key pair (more with --client NAME)
    allowed_clients/*.key             public keys of the clients the daemon accepts

The daemon needs `server.key_secret` and `allowed_clients/`; a client needs its own
`NAME.key_secret` and the daemon's `server.key` (public). Keys are Z85 text in
ZeroMQ's certificate format, so clients in other languages can read them too. Folders
are made 0700 and secret files 0600 whatever the umask (public files 0644).

Loopback TCP is reachable by every user of the machine, so a daemon binding it without
`--keys` uses the *local* key folder, `local_keys_dir()`: `$XDG_RUNTIME_DIR/sasprobe`
(else `/tmp/sasprobe-UID`), a private folder of the user created with a server and a
client pair on first use. The CLI and the Python clients load it by themselves for a
loopback TCP endpoint, so nothing needs typing, and other users cannot authenticate.
`ipc://` sockets are guarded by their file permissions (0600) instead and use no keys.
"""

from __future__ import annotations

import logging
import os
import shutil
import stat
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")

SERVER_NAME = "server"
LOCAL_KEYS_NAME = "sasprobe"  # inside $XDG_RUNTIME_DIR
REFUSAL_LOG_INTERVAL_S = 10.0  # the daemon logs refused client keys at most this often
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


def _private_dir(path: Path) -> None:
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(path, 0o700)  # mkdir's mode is cut by the umask only, never widened: make it exact


def generate_keys(directory: Path, clients: tuple[str, ...] = (DEFAULT_CLIENT_NAME,)) -> list[Path]:
    """Create the server pair (unless present) and one allowed pair per client name; return new
    files."""
    import zmq.auth

    directory = Path(directory)
    allowed = directory / ALLOWED_DIR
    for name in (SERVER_NAME, *clients):
        if not name or "/" in name or name.startswith("."):
            raise UserError(f"key name '{name}' is not a plain file name")
    try:
        _private_dir(directory)
        _private_dir(allowed)
        created: list[Path] = []
        for name in (SERVER_NAME, *clients):
            public = directory / f"{name}.key"
            if public.exists():
                if name != SERVER_NAME:
                    raise UserError(f"{public} already exists; choose another client name")
                continue
            public_file, secret_file = zmq.auth.create_certificates(str(directory), name)
            os.chmod(public_file, 0o644)
            os.chmod(secret_file, 0o600)  # the secret half never readable to others
            created += [Path(public_file), Path(secret_file)]
            if name != SERVER_NAME:
                listed = allowed / f"{name}.key"
                listed.write_bytes(Path(public_file).read_bytes())
                os.chmod(listed, 0o644)
                created.append(listed)
    except OSError as exc:
        raise KeyFileError(f"{directory}: cannot write keys ({exc.strerror or exc})") from None
    return created


def local_keys_dir() -> Path:
    """Where this user's local key folder lives (not created here)."""
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    if runtime:
        return Path(runtime) / LOCAL_KEYS_NAME
    return Path(tempfile.gettempdir()) / f"sasprobe-{os.geteuid()}"


def _check_private(path: Path) -> None:
    """A folder of this user that nobody else can read or write, not a symlink; KeyFileError
    otherwise."""
    info = path.lstat()
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.geteuid() or info.st_mode & 0o077:
        raise KeyFileError(
            f"{path}: the local key folder must be a folder of yours that only you can use "
            f"(it is mode {stat.filemode(info.st_mode)}, owner uid {info.st_uid}); remove it"
        )


def ensure_local_keys() -> Path:
    """The local key folder, created with a server and a client pair when missing (the
    daemon's side).

    Two daemons starting at once race safely: each writes a complete folder under a
    temporary name and renames it into place; the loser uses the winner's."""
    path = local_keys_dir()
    try:
        if not path.exists():
            if not path.parent.is_dir():  # $XDG_RUNTIME_DIR named but not there
                _private_dir(path.parent)
            scratch = Path(tempfile.mkdtemp(prefix=f".{path.name}-", dir=path.parent))
            try:
                generate_keys(scratch)
                os.rename(scratch, path)
            except OSError:
                if not path.exists():
                    raise
            finally:
                shutil.rmtree(scratch, ignore_errors=True)
        _check_private(path)
    except OSError as exc:
        raise KeyFileError(
            f"{path}: cannot create the local key folder ({exc.strerror or exc})"
        ) from None
    return path


def local_client_keys() -> ClientKeys | None:
    """This user's local client keys, or None when no daemon of theirs has made them yet."""
    path = local_keys_dir()
    try:
        if not path.is_dir():
            return None
        _check_private(path)
    except OSError:
        return None
    return load_client_keys(path)


def _load(path: Path, need_secret: bool) -> tuple[bytes, bytes | None]:
    import zmq.auth

    from sasprobe.common.files import open_regular

    if not path.exists():
        raise KeyFileError(f"{path}: no such key file (create keys with `sasprobe keys DIR`)")
    open_regular(
        path, "key file", KeyFileError
    ).close()  # a FIFO or device would block zmq's reader
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
        raise KeyFileError(
            f"{allowed}: no allow-list folder (create keys with `sasprobe keys DIR`)"
        )
    return ServerKeys(public=public, secret=secret or b"", allowed_dir=allowed)


def load_client_keys(directory: Path, name: str = DEFAULT_CLIENT_NAME) -> ClientKeys:
    directory = Path(directory)
    public, secret = _load(directory / f"{name}.key_secret", need_secret=True)
    server_public, _ = _load(directory / f"{SERVER_NAME}.key", need_secret=False)
    return ClientKeys(public=public, secret=secret or b"", server_public=server_public)


class AllowList:
    """ZAP credentials provider: the public keys in allowed_clients/ (read again when one is
    not found, so a key added while the daemon runs is taken), refusals logged, rate-limited."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.refused = 0
        self._keys = self._read()
        self._last_log = -REFUSAL_LOG_INTERVAL_S
        self._unlogged = 0

    def _read(self) -> set[bytes]:
        import zmq.auth

        try:
            return set(zmq.auth.load_certificates(str(self.directory)))
        except (OSError, ValueError):
            return set()

    def callback(self, domain: str, key) -> bool:
        key = key.encode() if isinstance(key, str) else bytes(key)
        if key in self._keys:
            return True
        self._keys = self._read()
        if key in self._keys:
            return True
        self.refused += 1
        now = time.monotonic()
        if now - self._last_log >= REFUSAL_LOG_INTERVAL_S:
            more = f" ({self._unlogged} more since the last line)" if self._unlogged else ""
            log.warning(
                "refused a client whose CURVE public key %s is not in %s%s",
                key.decode(errors="replace"),
                self.directory,
                more,
            )
            self._last_log, self._unlogged = now, 0
        else:
            self._unlogged += 1
        return False


def start_authenticator(context, keys: ServerKeys):
    """A ZAP handler thread that accepts CURVE clients whose public key is in the allow-list
    (and logs those it refuses); `auth.allow_list.refused` counts them."""
    from zmq.auth.thread import ThreadAuthenticator

    auth = ThreadAuthenticator(context)
    auth.start()
    auth.allow_list = AllowList(keys.allowed_dir)
    auth.configure_curve_callback(domain="*", credentials_provider=auth.allow_list)
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
    from sasprobe.protocol.endpoints import check_ipc_path, parse_endpoint, socket_file_umask

    if keys is not None:
        make_curve_server(socket, keys)
    bound = []
    try:
        for endpoint in endpoints:
            parsed = parse_endpoint(endpoint)
            if parsed.transport == "ipc":
                check_ipc_path(parsed.path)
                with socket_file_umask():  # the socket file 0600 whatever the umask
                    socket.bind(endpoint)
            else:
                socket.bind(endpoint)
            bound.append(socket.getsockopt_string(zmq.LAST_ENDPOINT))
    except (zmq.ZMQError, UserError):
        socket.close(linger=0)
        raise
    return bound


def make_curve_client(socket, keys: ClientKeys) -> None:
    socket.curve_secretkey = keys.secret
    socket.curve_publickey = keys.public
    socket.curve_serverkey = keys.server_public
