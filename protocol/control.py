"""Control requests and replies: JSON over ZeroMQ REQ (or DEALER) to the daemon's ROUTER.

A request is one or two frames: a UTF-8 JSON object, then (only for `load`) the raw
bytes of a structure file. A reply has the same shape: a JSON object saying ok or
giving an error, then (only for `get_structure`) the file's bytes. Every malformed
request gets an error reply; see protocol/README.md for each command.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from sasprobe.protocol.scene import (
    DEFAULT_LIGHTS,
    HAPTIC_METHODS,
    SceneError,
    merge_lights,
    reject_constant,
    validate_clip_planes,
    validate_mark_label,
)

CONTROL_VERSION = 1
MAX_REQUEST_JSON_BYTES = 64 * 1024  # the JSON frame; structure bytes travel in frame 2
MAX_STRUCTURE_BYTES = 256 * 1024 * 1024  # the largest structure file `load` accepts
MAX_MESSAGE_BYTES = MAX_STRUCTURE_BYTES + MAX_REQUEST_JSON_BYTES  # larger frames drop the connection

COMMANDS = (
    "ping",
    "status",
    "get_scene",
    "get_structure",
    "load",
    "set",
    "record_start",
    "record_stop",
    "shutdown",
    "mark",
    "findings",
)

# `set` fields and the JSON types they take (semantic limits, such as the probe radius's
# upper bound and the device's stiffness limit, are checked by the daemon).
SET_FIELDS = {
    "probe_radius_A": "number > 0",
    "stiffness_n_per_mm": "number ≥ 0",
    "damping_n_s_per_m": "number ≥ 0",
    "method": f"one of {', '.join(HAPTIC_METHODS)}",
    "cube_half_A": "number > 0, or null to fit the molecule",
    "nav_cube_enabled": "true or false",
    "clip_planes": "list of [a, b, c, d]",
    "lights": "object (partial updates merge)",
}


class ProtocolError(ValueError):
    """A request or reply that breaks the protocol; the message is the one-line error reply."""


@dataclass
class Request:
    cmd: str
    args: dict = field(default_factory=dict)
    id: object = None  # echoed in the reply so asynchronous (DEALER) clients can match replies
    data: bytes | None = None  # frame 2 (`load` only)
    version: int = CONTROL_VERSION


@dataclass
class Reply:
    ok: bool
    result: dict = field(default_factory=dict)
    error: str | None = None
    id: object = None
    data: bytes | None = None  # frame 2 (`get_structure` only)
    version: int = CONTROL_VERSION


def _dumps(obj: dict) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


def _loads(frame: bytes, what: str) -> dict:
    try:
        obj = json.loads(frame.decode("utf-8"), parse_constant=reject_constant)
    except UnicodeDecodeError:
        raise ProtocolError(f"{what} is not UTF-8 text") from None
    except ValueError as exc:
        raise ProtocolError(f"{what} is not valid JSON ({str(exc).splitlines()[0]})") from None
    if not isinstance(obj, dict):
        raise ProtocolError(f"{what} must be a JSON object, not {type(obj).__name__}")
    return obj


def _check_version(obj: dict, what: str) -> int:
    version = obj.get("version", CONTROL_VERSION)
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ProtocolError(f"{what} version must be a positive integer")
    if version > CONTROL_VERSION:
        raise ProtocolError(f"{what} version {version} is newer than this reader's {CONTROL_VERSION}")
    return version


def encode_request(cmd: str, args: dict | None = None, id: object = None, data: bytes | None = None) -> list[bytes]:
    obj: dict = {"version": CONTROL_VERSION, "cmd": cmd, "args": args or {}}
    if id is not None:
        obj["id"] = id
    return [_dumps(obj)] + ([bytes(data)] if data is not None else [])


def decode_request(frames: list[bytes]) -> Request:
    """Parse and check a request's frames; ProtocolError says what is wrong in one line."""
    if not frames:
        raise ProtocolError("empty request")
    if len(frames) > 2:
        raise ProtocolError(f"a request has 1 or 2 frames, got {len(frames)}")
    if len(frames[0]) > MAX_REQUEST_JSON_BYTES:
        raise ProtocolError(f"request of {len(frames[0])} bytes is larger than {MAX_REQUEST_JSON_BYTES}")
    obj = _loads(frames[0], "request")
    version = _check_version(obj, "request")
    cmd = obj.get("cmd")
    if not isinstance(cmd, str):
        raise ProtocolError("request needs a string 'cmd'")
    if cmd not in COMMANDS:
        raise ProtocolError(f"unknown command '{cmd[:40]}' (known: {', '.join(COMMANDS)})")
    args = obj.get("args", {})
    if not isinstance(args, dict):
        raise ProtocolError(f"'args' must be a JSON object, not {type(args).__name__}")
    data = frames[1] if len(frames) == 2 else None
    if data is not None and cmd != "load":
        raise ProtocolError(f"'{cmd}' takes no data frame")
    if data is not None and len(data) > MAX_STRUCTURE_BYTES:
        raise ProtocolError(f"structure data of {len(data)} bytes is larger than {MAX_STRUCTURE_BYTES}")
    req = Request(cmd=cmd, args=args, id=obj.get("id"), data=data, version=version)
    _check_args(req)
    return req


def encode_reply(reply: Reply) -> list[bytes]:
    obj: dict = {"version": CONTROL_VERSION, "ok": reply.ok}
    if reply.id is not None:
        obj["id"] = reply.id
    if reply.ok:
        obj["result"] = reply.result
    else:
        obj["error"] = reply.error or "error"
    return [_dumps(obj)] + ([bytes(reply.data)] if reply.data is not None else [])


def decode_reply(frames: list[bytes]) -> Reply:
    if not frames or len(frames) > 2:
        raise ProtocolError(f"a reply has 1 or 2 frames, got {len(frames)}")
    obj = _loads(frames[0], "reply")
    version = _check_version(obj, "reply")
    ok = obj.get("ok")
    if not isinstance(ok, bool):
        raise ProtocolError("reply needs a boolean 'ok'")
    result = obj.get("result", {})
    error = obj.get("error")
    if ok and not isinstance(result, dict):
        raise ProtocolError("reply 'result' must be an object")
    if not ok and not isinstance(error, str):
        raise ProtocolError("an error reply needs a string 'error'")
    return Reply(ok=ok, result=result if ok else {}, error=error, id=obj.get("id"),
                 data=frames[1] if len(frames) == 2 else None, version=version)


def _string(args: dict, key: str, cmd: str, required: bool = True) -> str | None:
    value = args.get(key)
    if value is None and not required:
        return None
    if not isinstance(value, str) or not value:
        raise ProtocolError(f"'{cmd}' needs a non-empty string '{key}'")
    return value


def _no_args(req: Request) -> None:
    if req.args:
        raise ProtocolError(f"'{req.cmd}' takes no arguments, got {', '.join(sorted(map(str, req.args)))}")


def _number(value, key: str, minimum: float, strict: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ProtocolError(f"'{key}' must be a finite number")
    if value < minimum or (strict and value == minimum):
        raise ProtocolError(f"'{key}' must be a {SET_FIELDS[key]}, got {value}")
    return float(value)


def validate_set_args(args: dict) -> dict:
    """Type-check the fields of a `set`; return them with numbers as floats."""
    if not args:
        raise ProtocolError(f"'set' needs at least one of: {', '.join(SET_FIELDS)}")
    unknown = sorted(str(k) for k in args if k not in SET_FIELDS)
    if unknown:
        raise ProtocolError(f"'set' does not know {', '.join(unknown)} (known: {', '.join(SET_FIELDS)})")
    out: dict = {}
    for key, value in args.items():
        if key == "probe_radius_A":
            out[key] = _number(value, key, 0.0, True)
        elif key in ("stiffness_n_per_mm", "damping_n_s_per_m"):
            out[key] = _number(value, key, 0.0, False)
        elif key == "cube_half_A":
            out[key] = None if value is None else _number(value, key, 0.0, True)
        elif key == "method":
            if value not in HAPTIC_METHODS:
                raise ProtocolError(f"'method' must be {SET_FIELDS[key]}, got {str(value)[:40]!r}")
            out[key] = value
        elif key == "nav_cube_enabled":
            if not isinstance(value, bool):
                raise ProtocolError("'nav_cube_enabled' must be true or false")
            out[key] = value
        else:  # clip_planes, lights: checked against the scene schema
            try:
                if key == "clip_planes":
                    out[key] = validate_clip_planes(value)
                else:
                    merge_lights(DEFAULT_LIGHTS, value)  # type check only: the daemon merges into its own
                    out[key] = value
            except SceneError as exc:
                raise ProtocolError(str(exc)) from None
    return out


def _check_args(req: Request) -> None:
    if req.cmd in ("ping", "get_scene", "get_structure", "record_stop", "shutdown"):
        _no_args(req)
    elif req.cmd == "status":
        unknown = set(req.args) - {"reset_stats"}
        if unknown or not isinstance(req.args.get("reset_stats", False), bool):
            raise ProtocolError("'status' takes only 'reset_stats' (true or false)")
    elif req.cmd == "record_start":
        _string(req.args, "path", req.cmd)
        if set(req.args) - {"path"}:
            raise ProtocolError("'record_start' takes only 'path'")
    elif req.cmd == "load":
        if set(req.args) - {"path", "name", "keep_water"}:
            raise ProtocolError("'load' takes 'path', or 'name' with the file's bytes as frame 2, and 'keep_water'")
        if not isinstance(req.args.get("keep_water", False), bool):
            raise ProtocolError("'keep_water' must be true or false")
        if req.data is None:
            _string(req.args, "path", req.cmd)
        else:
            if "path" in req.args:
                raise ProtocolError("'load' takes either 'path' or a data frame, not both")
            _string(req.args, "name", req.cmd, required=False)
    elif req.cmd == "set":
        req.args = validate_set_args(req.args)
    elif req.cmd == "mark":
        if set(req.args) - {"label"}:
            raise ProtocolError("'mark' takes only 'label'")
        if "label" in req.args:
            try:
                validate_mark_label(req.args["label"])
            except SceneError as exc:
                raise ProtocolError(str(exc)) from None
    elif req.cmd == "findings":
        _string(req.args, "dir", req.cmd)
        if set(req.args) - {"dir", "probe_radius_A"}:
            raise ProtocolError("'findings' takes 'dir' and 'probe_radius_A'")
        if "probe_radius_A" in req.args:
            value = req.args["probe_radius_A"]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value <= 0:
                raise ProtocolError("'probe_radius_A' must be a number > 0")
