"""The protocol's machine-readable definitions (protocol/schemas/, shipped with the package).

- `pose.json`: the pose's binary layout and flag bits, one table from which the pose
  codec (protocol/pose.py) takes its struct format and flag values, the first recording
  format's `pose` channel schema is built (`pose_record_schema`) and the tables of
  protocol/README.md are rendered (`pose_table_markdown`, `flags_table_markdown`; the
  page carries a copy, which a test checks against the rendering);
- `ticks.json`: the binary layout of a recording's `ticks` channel (protocol/ticks.py's
  codec is built from it; `ticks_table_markdown` renders its README tables);
- JSON Schema 2020-12 for every JSON message: `scene.schema.json`, `control.schema.json`
  (every request and reply, `#/$defs/args.CMD` and `#/$defs/result.CMD`),
  `device.schema.json` and `control-record.schema.json` (recording channels),
  `events.schema.json` (the lines `sasprobe daemon` prints on stdout).

Schemas refer to each other by `$id` (`urn:sasprobe:NAME`); `bundled()` gives one that
carries what it refers to in its `$defs`, as a recording embeds it (MCAP schema encoding
`jsonschema`). Validation needs the `jsonschema` package, imported only by `validator()`.
"""

from __future__ import annotations

import copy
import functools
import json
from importlib import resources

DIALECT = "https://json-schema.org/draft/2020-12/schema"
URN = "urn:sasprobe:"
SCHEMA_FILES = {  # $id suffix -> file
    "scene": "scene.schema.json",
    "control": "control.schema.json",
    "device": "device.schema.json",
    "control-record": "control-record.schema.json",
    "events": "events.schema.json",
}
_STRUCT_CODES = {
    "uint16": "H",
    "uint32": "I",
    "uint64": "Q",
    "int32": "i",
    "int64": "q",
    "float64": "d",
}
_SIZES = {"uint16": 2, "uint32": 4, "uint64": 8, "int32": 4, "int64": 8, "float64": 8}


def _read(filename: str) -> dict:
    return json.loads(
        resources.files(__package__).joinpath("schemas", filename).read_text(encoding="utf-8")
    )


@functools.cache
def pose_layout() -> dict:
    """pose.json: {"version", "byte_order", "size", "fields": [...], "flags": [...]}."""
    return _read("pose.json")


@functools.cache
def ticks_layout() -> dict:
    """ticks.json: {"version", "byte_order", "header", "record", "device_flags", "errors"}."""
    return _read("ticks.json")


def ticks_schema() -> dict:
    """ticks.json with pose.json under `pose`: the standalone layout a recording embeds for
    its `ticks` channel."""
    return {**ticks_layout(), "pose": pose_layout()}


def pose_struct_format() -> str:
    """The layout as a Python `struct` format (little-endian, no padding)."""
    return "<" + "".join(
        ("" if f["count"] == 1 else str(f["count"])) + _STRUCT_CODES[f["type"]]
        for f in pose_layout()["fields"]
    )


def pose_flag(name: str) -> int:
    """A flag's value (1 << bit) by its name in pose.json."""
    for flag in pose_layout()["flags"]:
        if flag["name"] == name:
            return 1 << flag["bit"]
    raise KeyError(name)


def field_size(field: dict) -> int:
    if field["type"] == "pose":
        return pose_layout()["size"] * field["count"]
    return _SIZES[field["type"]] * field["count"]


@functools.cache
def schema(name: str) -> dict:
    """A schema by name: scene, control, device, control-record, or pose (the recording's
    `pose` channel, built from pose.json)."""
    return pose_record_schema() if name == "pose" else _read(SCHEMA_FILES[name])


def pose_record_schema() -> dict:
    """The first recording format's `pose` channel: the pose's fields as JSON, under their
    record names."""
    layout = pose_layout()
    properties = {}
    for f in layout["fields"]:
        if f["record"] is None:
            continue
        base = f["type"]
        if base == "float64":
            item = {"type": "number"}
            prop = (
                item
                if f["count"] == 1
                else {
                    "type": "array",
                    "minItems": f["count"],
                    "maxItems": f["count"],
                    "items": item,
                }
            )
        else:
            bits = _SIZES[base] * 8
            low, high = (
                (0, 2**bits - 1)
                if base.startswith("u")
                else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
            )
            if f["name"] == "flags":
                high = 2 ** len(layout["flags"]) - 1  # bits not in the table are 0
            prop = {"type": "integer", "minimum": low, "maximum": high}
        properties[f["record"]] = {**prop, "description": f["meaning"]}
    return {
        "$schema": DIALECT,
        "$id": URN + "pose",
        "title": "sasprobe.Pose",
        "description": (
            f"Recording channel `pose` (first recording format): the published pose "
            f"(layout version {layout['version']}) as JSON"
        ),
        "type": "object",
        "required": list(properties),
        "additionalProperties": False,
        "properties": properties,
    }


def _references(node, found: set) -> None:
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith(URN):
            found.add(ref.split("#", 1)[0][len(URN) :])
        for value in node.values():
            _references(value, found)
    elif isinstance(node, list):
        for value in node:
            _references(value, found)


def _referenced(name: str) -> list[str]:
    """The other schemas `name` refers to, directly or through them."""
    seen, todo = set(), [name]
    while todo:
        found: set = set()
        _references(schema(todo.pop()), found)
        for other in found - seen - {name}:
            seen.add(other)
            todo.append(other)
    return sorted(seen)


@functools.cache
def bundled(name: str) -> dict:
    """The schema with every schema it refers to embedded in its `$defs` (each keeps its
    `$id`), so it stands alone: what a recording carries for its channel."""
    out = copy.deepcopy(schema(name))
    defs = out.setdefault("$defs", {})
    for other in _referenced(name):
        embedded = copy.deepcopy(schema(other))
        embedded.pop("$schema", None)
        defs[URN + other] = embedded
    return out


def channel_schemas() -> dict[str, dict]:
    """The recording's JSON channels and their standalone schemas, in the order they are
    registered (the `ticks` channel's layout is `ticks_schema()`)."""
    return {"scene": bundled("scene"), "control": bundled("control-record")}


@functools.cache
def _registry():
    from referencing import Registry, Resource

    return Registry().with_resources(
        (URN + name, Resource.from_contents(schema(name))) for name in (*SCHEMA_FILES, "pose")
    )


@functools.cache
def validator(ref: str):
    """A jsonschema validator for `ref`, e.g. "scene", "control#/$defs/result.set"."""
    from jsonschema import Draft202012Validator

    return Draft202012Validator({"$ref": URN + ref}, registry=_registry())


def validation_errors(ref: str, instance) -> list[str]:
    """Every way `instance` breaks the schema `ref`, one line each (none: it is valid)."""
    errors = sorted(validator(ref).iter_errors(instance), key=lambda e: list(e.absolute_path))
    return [f"{'/'.join(map(str, e.absolute_path)) or '(root)'}: {e.message[:300]}" for e in errors]


def _layout_table(fields: list[dict]) -> str:
    rows = ["| offset | size | type | field | unit / meaning |", "|---:|---:|---|---|---|"]
    for f in fields:
        typ = f["type"] if f["count"] == 1 else f"{f['type']}[{f['count']}]"
        name = f["name"] if f.get("reserved") else f"`{f['name']}`"
        rows.append(f"| {f['offset']} | {field_size(f)} | {typ} | {name} | {f['meaning']} |")
    return "\n".join(rows)


def pose_table_markdown() -> str:
    """protocol/README.md's pose layout table."""
    return _layout_table(pose_layout()["fields"])


def ticks_table_markdown() -> str:
    """protocol/README.md's tables of the `ticks` channel: the message header, the tick
    record and its device flags."""
    layout = ticks_layout()
    flags = ["| bit | value | name | meaning |", "|---:|---:|---|---|"]
    flags += [
        f"| {f['bit']} | {1 << f['bit']} | {f['name']} | {f['meaning']} |"
        for f in layout["device_flags"]
    ]
    return "\n\n".join(
        (
            _layout_table(layout["header"]["fields"]),
            _layout_table(layout["record"]["fields"]),
            "\n".join(flags),
        )
    )


def flags_table_markdown() -> str:
    """protocol/README.md's flags table."""
    rows = ["| bit | value | name | meaning |", "|---:|---:|---|---|"]
    rows += [
        f"| {f['bit']} | {1 << f['bit']} | {f['name']} | {f['meaning']} |"
        for f in pose_layout()["flags"]
    ]
    return "\n".join(rows)
