"""Control requests and replies: JSON over ZeroMQ REQ (or DEALER) to the daemon's ROUTER.

A request is one or two frames: a UTF-8 JSON object, then (only for `load`) the raw
bytes of a structure file. A reply has the same shape: a JSON object saying ok or
giving an error, then (only for `get_structure`) the file's bytes. Every malformed
request gets an error reply; see protocol/README.md for each command.

What the JSON may hold is bounded so that no request can make its reader misbehave
(protocol/strict_json.py): numbers must be finite doubles (`1e400` is refused, not read as
inf), integers at most MAX_INTEGER_DIGITS digits, nesting at most MAX_NESTING deep; each
limit is refused by name. Every frame of a message counts against MAX_MESSAGE_BYTES.

The request's `id` is read before anything else is checked, so every error reply carries
it, except where it cannot be read: a first frame over MAX_REQUEST_JSON_BYTES, not UTF-8,
not one JSON object, or with an `id` that is not valid. A frame that is JSON but breaks a
number or nesting limit gets its id from its outermost members (`outer_members`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from sasprobe.protocol.scene import (
    COLOR_SCHEMES,
    DEFAULT_LIGHTS,
    HAPTIC_METHODS,
    SceneError,
    merge_lights,
    validate_clip_planes,
    validate_color_scheme,
    validate_mark_label,
)
from sasprobe.protocol.strict_json import (  # noqa: F401  the limits, beside the others
    MAX_INTEGER_DIGITS,
    MAX_NESTING,
    JSONRefused,
    outer_members,
    read_object,
)

CONTROL_VERSION = 1
MAX_REQUEST_JSON_BYTES = 64 * 1024  # the JSON frame; structure bytes travel in frame 2
MAX_STRUCTURE_BYTES = 256 * 1024 * 1024  # the largest structure file `load` accepts
# all frames together; a larger frame drops the connection
MAX_MESSAGE_BYTES = MAX_STRUCTURE_BYTES + MAX_REQUEST_JSON_BYTES
MAX_NAME_CHARS = 200  # `load`'s name and other short strings

# what `get_structure` serves: the file as loaded, or its parsed arrays
STRUCTURE_FORMS = ("file", "arrays")
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
    "view",
    "clutch",
    "recentre",
    "mark",
    "findings",
)

# `set` fields and the JSON types they take (semantic limits, such as the probe radius's
# upper bound and the device's stiffness limit, are checked by the daemon).
SET_FIELDS = {
    "probe_radius_A": "number > 0",
    "stiffness_n_per_mm": "number > 0",
    "damping_n_s_per_m": "number ≥ 0",
    "method": f"one of {', '.join(HAPTIC_METHODS)}",
    "cube_half_A": 'number > 0, "fit" (the whole molecule) or null (the default size)',
    "nav_cube_enabled": "true or false",
    "clip_planes": "list of [a, b, c, d]",
    "lights": "object (partial updates merge)",
    "color_scheme": f"one of {', '.join(COLOR_SCHEMES)}, or null for each renderer's default",
}


class ProtocolError(ValueError):
    """A request or reply that breaks the protocol; the message is the one-line error reply.
    `request_id` is the request's id when it could be read, so the error reply echoes it."""

    def __init__(self, message: str, request_id: object = None) -> None:
        super().__init__(message)
        self.request_id = request_id


@dataclass
class Request:
    cmd: str
    args: dict = field(default_factory=dict)
    id: object = None  # echoed in the reply so asynchronous (DEALER) clients can match replies
    data: bytes | None = None  # frame 2 (`load` only)
    version: int = CONTROL_VERSION


@dataclass
class ControlReply:
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
        return read_object(frame, what)
    except JSONRefused as exc:
        raise ProtocolError(str(exc)) from None


def _check_version(obj: dict, what: str) -> int:
    version = obj.get("version", CONTROL_VERSION)
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ProtocolError(f"{what} version must be a positive integer")
    if version > CONTROL_VERSION:
        raise ProtocolError(
            f"{what} version {version} is newer than this reader's {CONTROL_VERSION}"
        )
    return version


def encode_request(
    cmd: str, args: dict | None = None, id: object = None, data: bytes | None = None
) -> list[bytes]:
    obj: dict = {"version": CONTROL_VERSION, "cmd": cmd, "args": args or {}}
    if id is not None:
        obj["id"] = id
    return [_dumps(obj)] + ([bytes(data)] if data is not None else [])


def decode_request(frames: list) -> Request:
    """Parse and check a request's frames (bytes or any buffer, e.g. zmq.Frame); ProtocolError
    says what is wrong in one line, with the request's id wherever it could be read. The data
    frame comes back as a memoryview (no copy)."""
    if not frames:
        raise ProtocolError("empty request")
    if len(frames[0]) > MAX_REQUEST_JSON_BYTES:
        raise ProtocolError(
            f"request of {len(frames[0])} bytes is larger than {MAX_REQUEST_JSON_BYTES}"
        )
    frame = bytes(frames[0])
    try:
        obj = read_object(frame, "request")
    except JSONRefused as exc:
        raise ProtocolError(str(exc), _id_of_refused(frame) if exc.limit else None) from None
    request_id = request_id_of(obj)
    try:
        total = sum(len(f) for f in frames)
        if total > MAX_MESSAGE_BYTES:
            raise ProtocolError(
                f"request of {total} bytes in {len(frames)} frames is larger than "
                f"{MAX_MESSAGE_BYTES}"
            )
        req = _request(obj, frames)
    except ProtocolError as exc:
        raise ProtocolError(str(exc), request_id) from None
    req.id = request_id
    return req


def _id_of_refused(frame: bytes):
    """The id of a request that is JSON but breaks a number or nesting limit, if valid."""
    members = outer_members(frame)
    try:
        return None if members is None else request_id_of(members)
    except ProtocolError:
        return None


def request_id_of(obj: dict):
    """The request's `id`, checked first so that every later error reply can echo it: a string
    of at most MAX_NAME_CHARS characters or a number, or absent (None). Anything else is
    refused, and that error reply carries no id."""
    value = obj.get("id")
    if value is None and "id" not in obj:
        return None
    if isinstance(value, str) and len(value) <= MAX_NAME_CHARS:
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return value
    raise ProtocolError(f"'id' must be a string of at most {MAX_NAME_CHARS} characters or a number")


def _request(obj: dict, frames: list) -> Request:
    if len(frames) > 2:
        raise ProtocolError(f"a request has 1 or 2 frames, got {len(frames)}")
    version = _check_version(obj, "request")
    cmd = obj.get("cmd")
    if not isinstance(cmd, str):
        raise ProtocolError("request needs a string 'cmd'")
    if cmd not in COMMANDS:
        raise ProtocolError(f"unknown command '{cmd[:40]}' (known: {', '.join(COMMANDS)})")
    args = obj.get("args", {})
    if not isinstance(args, dict):
        raise ProtocolError(f"'args' must be a JSON object, not {type(args).__name__}")
    data = memoryview(frames[1]) if len(frames) == 2 else None
    if data is not None and cmd != "load":
        raise ProtocolError(f"'{cmd}' takes no data frame")
    if data is not None and len(data) > MAX_STRUCTURE_BYTES:
        raise ProtocolError(
            f"structure data of {len(data)} bytes is larger than {MAX_STRUCTURE_BYTES}"
        )
    req = Request(cmd=cmd, args=args, data=data, version=version)
    _check_args(req)
    return req


def encode_reply(reply: ControlReply) -> list:
    obj: dict = {"version": CONTROL_VERSION, "ok": reply.ok}
    if reply.id is not None:
        obj["id"] = reply.id
    if reply.ok:
        obj["result"] = reply.result
    else:
        obj["error"] = reply.error or "error"
    # any buffer: sent without a copy
    return [_dumps(obj)] + ([reply.data] if reply.data is not None else [])


def decode_reply(frames: list[bytes]) -> ControlReply:
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
    return ControlReply(
        ok=ok,
        result=result if ok else {},
        error=error,
        id=obj.get("id"),
        data=frames[1] if len(frames) == 2 else None,
        version=version,
    )


def _string(args: dict, key: str, cmd: str, required: bool = True, limit: int = 4096) -> str | None:
    value = args.get(key)
    if value is None and not required:
        return None
    if not isinstance(value, str) or not value:
        raise ProtocolError(f"'{cmd}' needs a non-empty string '{key}'")
    if len(value) > limit or "\x00" in value:
        raise ProtocolError(f"'{cmd}': '{key}' must be at most {limit} characters, without NUL")
    return value


def _no_args(req: Request) -> None:
    if req.args:
        raise ProtocolError(
            f"'{req.cmd}' takes no arguments, got {', '.join(sorted(map(str, req.args)))}"
        )


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
        raise ProtocolError(
            f"'set' does not know {', '.join(unknown)} (known: {', '.join(SET_FIELDS)})"
        )
    out: dict = {}
    for key, value in args.items():
        if key in ("probe_radius_A", "stiffness_n_per_mm"):
            out[key] = _number(value, key, 0.0, True)
        elif key == "damping_n_s_per_m":
            out[key] = _number(value, key, 0.0, False)
        elif key == "cube_half_A":
            out[key] = value if value is None or value == "fit" else _number(value, key, 0.0, True)
        elif key == "method":
            if value not in HAPTIC_METHODS:
                raise ProtocolError(f"'method' must be {SET_FIELDS[key]}, got {str(value)[:40]!r}")
            out[key] = value
        elif key == "nav_cube_enabled":
            if not isinstance(value, bool):
                raise ProtocolError("'nav_cube_enabled' must be true or false")
            out[key] = value
        else:  # clip_planes, lights, color_scheme: checked against the scene schema
            try:
                if key == "color_scheme":
                    out[key] = validate_color_scheme(value)
                elif key == "clip_planes":
                    out[key] = validate_clip_planes(value)
                else:
                    # type check only: the daemon merges into its own
                    merge_lights(DEFAULT_LIGHTS, value)
                    out[key] = value
            except SceneError as exc:
                raise ProtocolError(str(exc)) from None
    return out


def _check_args(req: Request) -> None:
    if req.cmd in ("ping", "get_scene", "record_stop", "shutdown"):
        _no_args(req)
    elif req.cmd == "get_structure":
        if set(req.args) - {"form"} or req.args.get("form", "file") not in STRUCTURE_FORMS:
            raise ProtocolError(
                f"'get_structure' takes only 'form' ({' or '.join(map(repr, STRUCTURE_FORMS))})"
            )
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
            raise ProtocolError(
                "'load' takes 'path', or 'name' with the file's bytes as frame 2, and 'keep_water'"
            )
        if not isinstance(req.args.get("keep_water", False), bool):
            raise ProtocolError("'keep_water' must be true or false")
        if req.data is None:
            if "name" in req.args:
                raise ProtocolError("'load' takes 'name' only with the file's bytes as frame 2")
            _string(req.args, "path", req.cmd)
        else:
            if "path" in req.args:
                raise ProtocolError("'load' takes either 'path' or a data frame, not both")
            _string(req.args, "name", req.cmd, required=False, limit=MAX_NAME_CHARS)
    elif req.cmd == "set":
        req.args = validate_set_args(req.args)
    elif req.cmd == "view":
        rotation = req.args.get("rotation")
        if set(req.args) != {"rotation"} or not _is_matrix3(rotation):
            raise ProtocolError(
                "'view' takes 'rotation': 3 rows of 3 finite "
                "numbers (device frame -> molecule frame)"
            )
    elif req.cmd == "clutch":
        if set(req.args) != {"held"} or not isinstance(req.args["held"], bool):
            raise ProtocolError("'clutch' takes 'held' (true or false)")
    elif req.cmd == "recentre":
        _no_args(req)

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
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not math.isfinite(value)
                or value <= 0
            ):
                raise ProtocolError("'probe_radius_A' must be a number > 0")


def _is_matrix3(value) -> bool:
    return (
        isinstance(value, list)
        and len(value) == 3
        and all(
            isinstance(row, list)
            and len(row) == 3
            and all(
                not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x)
                for x in row
            )
            for row in value
        )
    )
