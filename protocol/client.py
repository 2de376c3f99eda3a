"""Clients of the daemon: a subscriber (latest pose + current scene) and a control client.

The subscriber never blocks its caller longer than asked: `poll()` drains whatever has
arrived and returns, so a renderer calls it once per frame and draws the newest pose.
Messages that break the protocol are dropped and counted, never raised.

Keys: without explicit ones, a client of a loopback TCP endpoint uses this user's local
CURVE keys (protocol/security.py), as the daemon does; when nothing comes, the error
line says why (protocol/handshake.py): a refused key, a missing one, a wrong server
key, or no daemon at all.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from pathlib import Path

import zmq
from sasprobe.protocol.control import ControlReply, ProtocolError, decode_reply, encode_request
from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT, DEFAULT_PUB_ENDPOINT, parse_endpoint
from sasprobe.protocol.handshake import ConnectionWatch
from sasprobe.protocol.pose import POSE_TOPIC, Pose, PoseDecodeError, decode_pose
from sasprobe.protocol.scene import SCENE_TOPIC, SceneError, decode_scene
from sasprobe.protocol.security import ClientKeys, local_client_keys, make_curve_client

from sasprobe.common.errors import UserError


class ControlError(UserError):
    """The daemon did not answer, or answered with an error (the message says which)."""


def keys_for(endpoint: str, keys: ClientKeys | None) -> ClientKeys | None:
    """The keys a client uses: the given ones; for loopback TCP, else this user's local keys."""
    if keys is not None:
        return keys
    parsed = parse_endpoint(endpoint)
    return local_client_keys() if parsed.transport == "tcp" and parsed.is_loopback else None


class Subscriber:
    """Subscribes to pose and scene; keeps the latest of each and counts what it saw."""

    def __init__(
        self,
        endpoint: str = DEFAULT_PUB_ENDPOINT,
        keys: ClientKeys | None = None,
        context: zmq.Context | None = None,
        rcvhwm: int = 10000,
    ) -> None:
        local = keys is None
        keys = keys_for(endpoint, keys)
        self.endpoint = endpoint
        self._context = context or zmq.Context.instance()
        self._socket = self._context.socket(zmq.SUB)
        self._socket.linger = 0
        self._socket.rcvhwm = rcvhwm
        if keys is not None:
            make_curve_client(self._socket, keys)
        self.watch = ConnectionWatch(
            self._socket, endpoint, keys is not None, local and keys is not None
        )
        self._socket.setsockopt(zmq.SUBSCRIBE, POSE_TOPIC)
        self._socket.setsockopt(zmq.SUBSCRIBE, SCENE_TOPIC)
        self._socket.connect(endpoint)
        self.pose: Pose | None = None  # the newest pose
        self.scene: dict | None = None  # the newest scene
        self.poses_received = 0
        self.scenes_received = 0
        self.malformed = 0  # messages dropped because they break the protocol
        # Poses lost between two received ones: gaps in `seq` beyond the scene's
        # `pose_every`, counted once a scene has said how far apart poses are.
        self.missed = 0
        self.last_error: str | None = None  # why the last malformed message was dropped

    def poll(self, timeout_s: float = 0.0) -> list[Pose]:
        """Wait up to timeout_s for a message, then take the queued ones without blocking:
        at most a queue's worth (rcvhwm), so a caller slower than the publisher (a starved
        process against a 1 kHz daemon) still gets control back; the rest waits for the
        next call, and what the queue could not hold shows in `missed`.

        Returns the poses received by this call, oldest first; `pose` and `scene` hold
        the newest of each.
        """
        received: list[Pose] = []
        if timeout_s > 0 and not self._socket.poll(int(timeout_s * 1000)):
            return received
        for _ in range(self._socket.rcvhwm):
            try:
                frames = self._socket.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                break
            pose = self._handle(frames)
            if pose is not None:
                received.append(pose)
        return received

    def _handle(self, frames: list[bytes]) -> Pose | None:
        try:
            if len(frames) != 2:
                raise ValueError(f"expected [topic, payload], got {len(frames)} frames")
            topic, payload = frames
            if topic == POSE_TOPIC:
                pose = decode_pose(payload)
                if self.scene is not None and self.pose is not None:
                    stride = self.scene.get("pose_every", 1)
                    if pose.seq > self.pose.seq + stride:
                        self.missed += (pose.seq - self.pose.seq) // stride - 1
                self.pose = pose
                self.poses_received += 1
                return pose
            if topic == SCENE_TOPIC:
                self.scene = decode_scene(payload)
                self.scenes_received += 1
                return None
            raise ValueError(f"unknown topic {topic[:20]!r}")
        except (PoseDecodeError, SceneError, ValueError) as exc:
            self.malformed += 1
            self.last_error = str(exc)
            return None

    def wait_for_scene(self, timeout_s: float = 3.0) -> dict:
        """Poll until a scene has arrived (the daemon sends one at least once a second)."""
        deadline = time.monotonic() + timeout_s
        while self.scene is None:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise ControlError(
                    f"no scene from {self.endpoint} within {timeout_s:g} s: {self.watch.explain()}"
                )
            self.poll(min(remaining, 0.1))
        return self.scene

    def close(self) -> None:
        self.watch.close()
        self._socket.close(linger=0)

    def __enter__(self) -> Subscriber:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ControlClient:
    """Sends control requests (REQ socket); a lost reply resets the socket (lazy pirate)."""

    def __init__(
        self,
        endpoint: str = DEFAULT_CTL_ENDPOINT,
        keys: ClientKeys | None = None,
        timeout_s: float = 3.0,
        context: zmq.Context | None = None,
    ) -> None:
        self._local_keys = keys is None  # None asks for this user's local keys where they apply
        self._keys = keys_for(endpoint, keys)
        self.endpoint = endpoint
        self.timeout_s = timeout_s
        self._context = context or zmq.Context.instance()
        self._ids = itertools.count(1)
        self._socket: zmq.Socket | None = None
        self._watch: ConnectionWatch | None = None

    def _open(self) -> zmq.Socket:
        if self._socket is None:
            sock = self._context.socket(zmq.REQ)
            sock.linger = 0
            if self._keys is not None:
                make_curve_client(sock, self._keys)
            self._watch = ConnectionWatch(
                sock,
                self.endpoint,
                self._keys is not None,
                self._local_keys and self._keys is not None,
            )
            sock.connect(self.endpoint)
            self._socket = sock
        return self._socket

    def request(
        self,
        cmd: str,
        args: dict | None = None,
        data: bytes | None = None,
        timeout_s: float | None = None,
    ) -> ControlReply:
        """One request and its reply (ok or not); ControlError when no valid reply comes in time."""
        sock = self._open()
        request_id = next(self._ids)
        sock.send_multipart(encode_request(cmd, args, id=request_id, data=data))
        timeout = self.timeout_s if timeout_s is None else timeout_s
        if not sock.poll(int(timeout * 1000)):
            why = self._watch.explain()
            self._reset()
            raise ControlError(
                f"no reply from the daemon at {self.endpoint} within {timeout:g} s: {why}"
            )
        try:
            reply = decode_reply(sock.recv_multipart())
        except ProtocolError as exc:
            raise ControlError(f"bad reply from {self.endpoint}: {exc}") from None
        if reply.id != request_id:
            self._reset()
            raise ControlError(f"reply from {self.endpoint} does not match the request")
        return reply

    def call(
        self, cmd: str, data: bytes | None = None, timeout_s: float | None = None, **args
    ) -> dict:
        """Send a command and return its result; ControlError carries the daemon's error line."""
        reply = self.request(cmd, args, data=data, timeout_s=timeout_s)
        if not reply.ok:
            raise ControlError(f"{cmd}: {reply.error}")
        return reply.result

    def ping(self) -> dict:
        return self.call("ping")

    def status(self, reset_stats: bool = False) -> dict:
        """The daemon's status; reset_stats starts a new measurement window first."""
        return self.call("status", **({"reset_stats": True} if reset_stats else {}))

    def get_scene(self) -> dict:
        return self.call("get_scene")

    def get_structure(self, timeout_s: float = 30.0, form: str = "file") -> tuple[dict, bytes]:
        """The structure the daemon uses: (header with name, sha256, ..., the bytes): the file
        as loaded, or with `form` "arrays" its parsed arrays."""
        reply = self.request(
            "get_structure", {} if form == "file" else {"form": form}, timeout_s=timeout_s
        )
        if not reply.ok:
            raise ControlError(f"get_structure: {reply.error}")
        if reply.data is None:
            raise ControlError("get_structure: the reply carries no file bytes")
        return reply.result, reply.data

    def load(
        self,
        path: str | Path | None = None,
        data: bytes | None = None,
        name: str | None = None,
        timeout_s: float = 60.0,
        daemon_path: str | None = None,
    ) -> dict:
        """Load a structure: a local `path` (read here, sent as bytes), `data` bytes, or
        `daemon_path`, a file the daemon reads itself (only below its --load-dir)."""
        if daemon_path is not None:
            return self.call("load", timeout_s=timeout_s, path=str(daemon_path))
        if path is not None:
            path = Path(path)
            try:
                if not path.is_file():
                    raise ControlError(f"{path}: not a regular file")
                data, name = path.read_bytes(), name or path.name
            except OSError as exc:
                raise ControlError(f"{path}: cannot read ({exc.strerror or exc})") from None
        return self.call("load", data=data, timeout_s=timeout_s, **({"name": name} if name else {}))

    def set(self, **changes) -> dict:
        return self.call("set", **changes)

    def record_start(self, path: str | Path) -> dict:
        return self.call("record_start", path=str(path))

    def record_stop(self) -> dict:
        return self.call("record_stop")

    def shutdown(self) -> dict:
        return self.call("shutdown")

    def mark(self, label: str | None = None) -> dict:
        """Drop a mark at the probe's position: {"mark": {...}, "seq"}."""
        return self.call("mark", **({"label": label} if label else {}))

    def findings(self, out_dir: str | Path, probe_radius_A: float | None = None) -> dict:
        """Start the analysis of the daemon's recording so far into a folder on its host."""
        extra = {} if probe_radius_A is None else {"probe_radius_A": probe_radius_A}
        return self.call("findings", dir=str(out_dir), **extra)

    def _reset(self) -> None:
        if self._watch is not None:
            self._watch.close()
            self._watch = None
        if self._socket is not None:
            self._socket.close(linger=0)
            self._socket = None

    def close(self) -> None:
        self._reset()

    def __enter__(self) -> ControlClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class StructureFile:
    """The daemon's structure as `get_structure` serves it, its sha256 checked: the file
    (form "file": parse it with `sasprobe.molecule.parse_structure(data, name=name,
    source=source, keep_water=keep_water)`) or its parsed arrays (form "arrays":
    `sasprobe.molecule.packed.unpack_structure(data, name, source, sha256)`), either way
    the daemon's atoms (the protocol itself knows nothing of structures)."""

    name: str
    data: bytes
    keep_water: bool  # as the daemon loaded it
    source: str  # where it came from, for messages
    form: str = "file"
    sha256: str = ""  # of the file (the scene's structure.sha256)


def fetch_structure(
    ctl_endpoint: str = DEFAULT_CTL_ENDPOINT,
    keys: ClientKeys | None = None,
    timeout_s: float = 30.0,
    form: str = "file",
) -> StructureFile:
    """The daemon's structure, as a file or (`form` "arrays") its parsed arrays (no shared disk
    needed); ControlError if the bytes do not match their sha256."""
    import hashlib

    with ControlClient(ctl_endpoint, keys=keys, timeout_s=timeout_s) as client:
        header, data = client.get_structure(timeout_s=timeout_s, form=form)
    digest = header.get("sha256") if form == "file" else header.get("arrays_sha256")
    if hashlib.sha256(data).hexdigest() != digest:
        raise ControlError(f"structure from {ctl_endpoint} does not match its sha256")
    name = header.get("name", "structure")
    return StructureFile(
        name=name,
        data=data,
        keep_water=bool(header.get("keep_water", False)),
        source=f"{ctl_endpoint}:{name}",
        form=form,
        sha256=str(header.get("sha256", "")),
    )
