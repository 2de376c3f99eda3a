"""Every message a test receives from a daemon, checked against protocol/schemas/.

The schemas are made strict here (every object that lists its properties gets
`additionalProperties: false`), so a key the daemon sends but no schema documents fails
as well as a missing or mistyped one. Binary poses are decoded with the README-table
decoder of tests/references/pose.py (not sasprobe's codec), then checked against
pose.json and for the agreement of one tick's flags and fields.

`checking_clients()` (installed for the whole run by tests/conftest.py) wraps
`ControlClient.request` and `Subscriber._handle`, so every reply (its frames as received),
scene and pose a test receives through sasprobe's clients is checked; raw-socket tests call
`check_pose_payload` and `check_reply` themselves. `checking_recordings()` (installed the
same way) checks every message of every recording a test reads through sasprobe's reader
(`sasprobe.protocol.recording.Recording.items`, under the replay, `summarize`, the
findings and the renderer's playback alike) as the reader hands it out; a `ticks`
message is decoded with the README-table decoder of tests/references/ticks.py.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import json
import math

from sasprobe.protocol import schemas
from sasprobe.protocol.control import COMMANDS

from tests.references.pose import reference_decode  # imported here, not while poses pour in
from tests.references.ticks import readme_ticks_tables, reference_decode_ticks

_FLAG = {f["name"]: 1 << f["bit"] for f in schemas.pose_layout()["flags"]}
RECORDED_TOPICS = {
    "device": "device",  # the first recording format's
    "pose": "pose",  # the first recording format's
    "scene": "scene",
    "control": "control-record",
}  # JSON channel: schema
TICKS_TOPIC = "ticks"  # binary: protocol/README.md's tables


def _strict(node):
    if isinstance(node, dict):
        out = {key: _strict(value) for key, value in node.items()}
        if (
            out.get("type") == "object"
            and "properties" in out
            and "additionalProperties" not in out
        ):
            out["additionalProperties"] = False
        return out
    if isinstance(node, list):
        return [_strict(value) for value in node]
    return node


@functools.cache
def _validator(ref: str):
    from jsonschema import Draft202012Validator
    from referencing import Registry, Resource

    names = (*schemas.SCHEMA_FILES, "pose")
    registry = Registry().with_resources(
        (schemas.URN + name, Resource.from_contents(_strict(copy.deepcopy(schemas.schema(name)))))
        for name in names
    )
    return Draft202012Validator({"$ref": schemas.URN + ref}, registry=registry)


def assert_valid(ref: str, instance) -> None:
    """AssertionError listing every way `instance` breaks the (strict) schema `ref`."""
    errors = sorted(_validator(ref).iter_errors(instance), key=lambda e: list(e.absolute_path))
    if errors:
        lines = [
            f"{'/'.join(map(str, e.absolute_path)) or '(root)'}: {e.message[:200]}"
            for e in errors[:8]
        ]
        raise AssertionError(f"{ref}: {len(errors)} schema error(s):\n  " + "\n  ".join(lines))


def check_reply(cmd: str, reply_json: dict) -> None:
    """A decoded reply frame: the envelope, and for `ok` the command's result."""
    assert_valid("control#/$defs/reply", reply_json)
    if reply_json["ok"] and cmd in COMMANDS:
        assert_valid(f"control#/$defs/result.{cmd}", reply_json["result"])


def check_reply_frames(cmd: str, reply_frames: list) -> dict:
    """A reply's frames as they came off the socket: the JSON frame as sent (no key added or
    lost by a decoder), and a second frame exactly for a `get_structure` that succeeded.
    Returns the decoded JSON frame."""
    reply_json = json.loads(bytes(reply_frames[0]))
    check_reply(cmd, reply_json)
    frames = 2 if cmd == "get_structure" and reply_json["ok"] else 1
    assert len(reply_frames) == frames, f"a reply to {cmd!r} of {len(reply_frames)} frames"
    return reply_json


def check_raw_reply(request_frame: bytes, reply_frames: list) -> None:
    """A reply to a request sent on a raw socket: checked as the reply to the command the
    request names, or as a bare envelope when it names none."""
    try:
        request = json.loads(bytes(request_frame))
    except (ValueError, RecursionError):
        request = None
    cmd = request.get("cmd") if isinstance(request, dict) else None
    check_reply_frames(cmd if isinstance(cmd, str) else "", reply_frames)


def check_scene(scene: dict) -> None:
    assert_valid("scene", scene)


def check_pose_payload(payload: bytes) -> dict:
    """A pose as published, against pose.json: decoded with the README table's decoder, its
    version, reserved word and flag bits, finite numbers, one tick's fields agreeing with its
    flags. (The JSON Schema validator is too slow for 1000 poses a second; the recording's
    `pose` records, the same fields, are checked with it.) Returns the decoded fields."""
    layout = schemas.pose_layout()
    assert len(payload) >= layout["size"], f"pose of {len(payload)} bytes"
    raw = reference_decode(payload)
    assert raw["version"] == layout["version"] and raw["reserved"] == 0, raw
    assert raw["flags"] < 1 << len(layout["flags"]), (
        f"seq {raw['seq']}: undocumented flag bits in {raw['flags']}"
    )
    record = {
        f["record"]: (list(raw[f["name"]]) if f["count"] > 1 else raw[f["name"]])
        for f in layout["fields"]
        if f["record"] is not None
    }
    for f in layout["fields"]:
        if f["type"] == "float64":
            values = record[f["record"]] if f["count"] > 1 else [record[f["record"]]]
            assert all(map(math.isfinite, values)), f"seq {raw['seq']}: {f['name']} is not finite"
    check_pose_agreement(record)
    return raw


def check_pose_agreement(p: dict, live: bool = True) -> None:
    """What the flags say of one tick holds in its fields (record names); for a `live` device
    (any but a replay, whose device times are the recording's) the device time is on the
    host's clock: not after the publish time."""
    flags = p["flags"]
    assert bool(flags & _FLAG["contact"]) == (p["touched_atom"] >= 0), (
        f"seq {p['seq']}: contact flag {bool(flags & _FLAG['contact'])} "
        f"with touched_atom {p['touched_atom']}"
    )
    if flags & (_FLAG["fault"] | _FLAG["clutched"]):
        assert p["force_N"] == [0.0, 0.0, 0.0], (
            f"seq {p['seq']}: force {p['force_N']} with flags {flags}"
        )
    assert not (flags & _FLAG["fault"] and flags & _FLAG["ramping"]), (
        f"seq {p['seq']}: fault and ramping"
    )
    assert abs(math.sqrt(sum(q * q for q in p["orientation"])) - 1.0) < 1e-6, (
        f"seq {p['seq']}: orientation"
    )
    assert p["device_t_ns"] >= 0, f"seq {p['seq']}: device time {p['device_t_ns']}"
    assert not live or p["device_t_ns"] <= p["publish_t_ns"], (
        f"seq {p['seq']}: device time {p['device_t_ns']} not on the host's clock "
        f"before {p['publish_t_ns']}"
    )


def check_record(topic: str, record: dict, live: bool = True) -> None:
    """A recording's message by channel; a pose record also for the agreement of its fields
    (`live`: recorded from a live device, not a replay)."""
    assert_valid(RECORDED_TOPICS[topic], record)
    if topic == "pose":
        check_pose_agreement(record, live)


_checked_records: set = (
    set()
)  # hash((topic, raw JSON)) of records already checked: a file read again is not re-checked


_checked_ticks: dict = {}  # hash(ticks message) -> its first and last tick's device time


class RecordingCheck:
    """The checks of one recording read in file order: each message on a documented channel
    and valid for its schema (a `ticks` message for the README's layout), each pose's fields
    agreeing with its flags, its device time never decreasing and, for a live device (any
    but a replay), never after its publish time."""

    def __init__(self) -> None:
        self.device_kind: str | None = None  # the start record's
        self.device_t_ns = 0

    def item(self, topic: str, data: dict, raw: bytes) -> None:
        """One item as the reader gives it (`data` empty when it was not decoded)."""
        if topic in ("attachment", "metadata"):
            return
        if topic == TICKS_TOPIC:
            self.ticks(raw)
            return
        assert topic in RECORDED_TOPICS, (
            f"a recording's message on the undocumented channel {topic!r}"
        )
        record = data if data else json.loads(raw)
        key = hash((topic, bytes(raw)))
        if key not in _checked_records:
            check_record(topic, record, live=self.device_kind != "replay")
            _checked_records.add(key)
        if topic == "control" and record["cmd"] == "start" and self.device_kind is None:
            self.device_kind = record["args"]["device"]["kind"]
        elif topic == "pose":
            self.device_time(record)

    def device_time(self, pose: dict) -> None:
        assert pose["device_t_ns"] >= self.device_t_ns, (
            f"seq {pose['seq']}: device time {pose['device_t_ns']} before the last, "
            f"{self.device_t_ns}"
        )
        self.device_t_ns = pose["device_t_ns"]

    def ticks(self, raw: bytes) -> None:
        """A `ticks` message, decoded from the README's tables: its header, each tick's
        device flags and the fields they leave empty, its error text, its pose (a message
        checked before only for its device times)."""
        key = hash(bytes(raw))
        if key in _checked_ticks:
            first, last = _checked_ticks[key]
            self.device_time(first)
            self.device_time(last)
            return
        decoded = reference_decode_ticks(bytes(raw))
        header, ticks = decoded["header"], decoded["ticks"]
        _, record_rows, flags = readme_ticks_tables()
        assert header["version"] == 1 and header["reserved"] == 0, header
        assert header["count"] > 0 and header["record_size"] == record_rows[-1][0] + 200, header
        layout = schemas.pose_layout()
        known = sum(flags.values())
        seqs = [t["pose"]["seq"] for t in ticks]
        times: list[dict] = []
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), f"ticks {seqs} are not in a row"
        for tick in ticks:
            seq, dflags = tick["pose"]["seq"], tick["device_flags"]
            assert dflags & ~known == 0 and tick["reserved"] == 0, f"seq {seq}: device flags"
            if not dflags & flags["state"]:
                assert tick["t_ns"] == 0 and tick["buttons"] == 0, f"seq {seq}: no state, values"
                assert not dflags & flags["calibrated"], f"seq {seq}: no state, yet calibrated"
                assert tick["error"], f"seq {seq}: a read without a state and without an error"
            assert (tick["error"] is not None) == bool(dflags & flags["error"]), f"seq {seq}"
            assert tick["late_periods"] >= 0 and tick["read_ns"] >= 0, f"seq {seq}"
            pose = tick["pose"]
            assert pose["version"] == layout["version"] and pose["reserved"] == 0, pose
            assert pose["flags"] < 1 << len(layout["flags"]), f"seq {seq}: undocumented flags"
            record = {
                f["record"]: (list(pose[f["name"]]) if f["count"] > 1 else pose[f["name"]])
                for f in layout["fields"]
                if f["record"] is not None
            }
            check_pose_agreement(record, live=self.device_kind != "replay")
            self.device_time(record)
            times.append({"seq": seq, "device_t_ns": record["device_t_ns"]})
        _checked_ticks[key] = (times[0], times[-1])


def checked_items(items):
    """The items of one recording (sasprobe's reader), each checked as it is handed out.
    A failure is pytest's, which is no Exception: a reader cannot take it for a damaged file."""
    check = RecordingCheck()
    for item in items:
        try:
            check.item(item.topic, item.data, item.raw)
        except AssertionError as exc:
            why = str(exc)
        else:
            yield item
            continue
        import pytest

        pytest.fail(f"a recorded {item.topic} message: {why}", pytrace=False)


@contextlib.contextmanager
def checking_recordings():
    """Every recording read through sasprobe's reader is checked as it is read:
    `sasprobe.protocol.recording.Recording.items` is replaced by one that checks what it
    yields, for every module that reads through it."""
    from sasprobe.protocol import recording

    original = recording.Recording.items
    for ref in RECORDED_TOPICS.values():  # build the validators now, not while records pour in
        list(_validator(ref).iter_errors({}))

    @functools.wraps(original)
    def items(self, decode: bool = True):
        return checked_items(original(self, decode))

    recording.Recording.items = items
    try:
        yield
    finally:
        recording.Recording.items = original


@contextlib.contextmanager
def checking_clients():
    """Wrap sasprobe's ControlClient and Subscriber so every received message is checked:
    a reply as the frames the client received (captured where it decodes them), a pose or
    scene as its payload."""
    import threading

    from sasprobe.protocol import client

    original_request, original_handle = client.ControlClient.request, client.Subscriber._handle
    original_decode = client.decode_reply
    received = threading.local()  # the frames of the reply the calling thread's client decoded last
    for ref in (
        "scene",
        "control#/$defs/reply",
    ):  # build the validators now, not while messages pour in
        list(_validator(ref).iter_errors({}))

    def decode_reply(frames):
        received.frames = [bytes(f) for f in frames]
        return original_decode(frames)

    def request(self, cmd, args=None, data=None, timeout_s=None):
        received.frames = None
        reply = original_request(self, cmd, args, data=data, timeout_s=timeout_s)
        assert received.frames is not None, (
            f"the client returned a reply to {cmd!r} it did not decode"
        )
        check_reply_frames(cmd, received.frames)
        return reply

    def handle(self, frames):
        scenes = self.scenes_received
        pose = original_handle(self, frames)
        if pose is not None:
            check_pose_payload(bytes(frames[1]))
        elif self.scenes_received > scenes:
            check_scene(json.loads(bytes(frames[1])))
        return pose

    client.ControlClient.request, client.Subscriber._handle = request, handle
    client.decode_reply = decode_reply
    try:
        yield
    finally:
        client.ControlClient.request, client.Subscriber._handle = original_request, original_handle
        client.decode_reply = original_decode
