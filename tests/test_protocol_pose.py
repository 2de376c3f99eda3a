"""The pose message against the byte layout documented in protocol/README.md.

The reference decoder here is built from the README's table alone (offsets, sizes,
types), not from sasprobe.protocol.pose, so the code and the document are checked
against each other.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sasprobe.protocol.pose import (
    POSE_SIZE,
    POSE_VERSION,
    Pose,
    PoseDecodeError,
    decode_pose,
    encode_pose,
)

from tests.references.pose import README, readme_pose_table, reference_decode


def test_readme_table_is_contiguous_and_200_bytes():
    rows = readme_pose_table()
    assert len(rows) >= 15
    offset = 0
    for row_offset, size, _, name in rows:
        assert row_offset == offset, f"gap or overlap before {name}"
        offset += size
    assert offset == POSE_SIZE == 200


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
vec3 = st.lists(finite, min_size=3, max_size=3)


@settings(max_examples=200, deadline=None)
@given(
    seq=st.integers(0, 2**64 - 1),
    t=st.integers(-(2**63), 2**63 - 1),
    tp=st.integers(-(2**63), 2**63 - 1),
    proxy=vec3,
    goal=vec3,
    force=vec3,
    tip=vec3,
    quat=st.lists(finite, min_size=4, max_size=4),
    buttons=st.integers(0, 2**32 - 1),
    atom=st.integers(-1, 2**31 - 1),
    flags=st.integers(0, 2**16 - 1),
    center=vec3,
    half=finite,
)
def test_encoder_matches_readme_layout(
    seq, t, tp, proxy, goal, force, tip, quat, buttons, atom, flags, center, half
):
    pose = Pose(
        seq=seq,
        device_t_ns=t,
        publish_t_ns=tp,
        proxy_A=np.array(proxy),
        goal_A=np.array(goal),
        force_N=np.array(force),
        tip_mm=np.array(tip),
        orientation=np.array(quat),
        buttons=buttons,
        touched_atom=atom,
        flags=flags,
        cube_center_A=np.array(center),
        cube_half_A=half,
    )
    payload = encode_pose(pose)
    assert len(payload) == 200
    ref = reference_decode(payload)
    assert ref["version"] == POSE_VERSION
    assert ref["flags"] == flags and ref["buttons"] == buttons and ref["seq"] == seq
    assert ref["device_t_ns"] == t and ref["publish_t_ns"] == tp
    assert list(ref["proxy"]) == proxy and list(ref["goal"]) == goal and list(ref["force"]) == force
    assert list(ref["tip"]) == tip and list(ref["orientation"]) == quat
    assert ref["touched_atom"] == atom and ref["reserved"] == 0
    assert list(ref["cube_center"]) == center and ref["cube_half"] == half
    back = decode_pose(payload)
    assert back.seq == seq and back.flags == flags and back.touched_atom == atom
    assert back.force_N.tolist() == force and back.cube_half_A == half


def test_newer_versions_append_and_old_readers_skip_the_rest():
    payload = bytearray(encode_pose(Pose(seq=7, force_N=np.array([1.0, 2.0, 3.0]))))
    struct.pack_into("<H", payload, 0, POSE_VERSION + 1)
    pose = decode_pose(bytes(payload) + b"\x01" * 24)  # a version-2 payload with appended fields
    assert (
        pose.seq == 7
        and pose.force_N.tolist() == [1.0, 2.0, 3.0]
        and pose.version == POSE_VERSION + 1
    )


@pytest.mark.parametrize(
    "payload", [b"", b"\x01", encode_pose(Pose())[:199], b"\x00\x00" + bytes(198)]
)
def test_short_or_older_payloads_are_rejected(payload):
    with pytest.raises(PoseDecodeError):
        decode_pose(payload)


def test_the_readme_tables_and_the_codec_come_from_pose_json():
    """The README's pose and flags tables and struct format are copies of what
    sasprobe.protocol.schemas renders from pose.json; a copy that differs fails, printing the
    rendering to paste."""
    from sasprobe.protocol import schemas
    from sasprobe.protocol.ticks import POSE_RECORD_FIELDS

    text = README.read_text()
    for rendered in (
        schemas.pose_table_markdown(),
        schemas.flags_table_markdown(),
        f"Python `struct` format: `{schemas.pose_struct_format()}`",
    ):
        assert rendered in text, (
            f"protocol/README.md differs from schemas/pose.json's rendering:\n{rendered}"
        )
    layout = schemas.pose_layout()
    assert list(readme_pose_table()) == [
        (
            f["offset"],
            schemas.field_size(f),
            f["type"] + (f"[{f['count']}]" if f["count"] > 1 else ""),
            f["name"],
        )
        for f in layout["fields"]
    ]
    pose_fields = set(Pose.__dataclass_fields__) - {"version"}
    assert (
        set(POSE_RECORD_FIELDS)
        == pose_fields
        == {f["record"] for f in layout["fields"] if f["record"]}
    )
