"""The recording's `ticks` channel: the codec against protocol/README.md's tables, longer
records of a later version, damaged messages, and the blocks a recording is read in."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sasprobe.protocol import schemas
from sasprobe.protocol.pose import Pose
from sasprobe.protocol.ticks import (
    HEADER,
    RECORD_SIZE,
    TickBlock,
    TicksDecodeError,
    TicksPacker,
    decode_ticks,
)

from tests.references.pose import README
from tests.references.ticks import readme_ticks_tables, reference_decode_ticks

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
number = st.floats(width=64)  # NaN and infinities too: a reading may have them
vector = st.lists(number, min_size=3, max_size=3)
tick = st.fixed_dictionaries(
    {
        "state": st.none()
        | st.tuples(
            st.integers(1, 2**62),
            vector,
            st.lists(number, min_size=4, max_size=4),
            vector,
            st.integers(0, 2**32 - 1),
            st.booleans(),
        ),
        "error": st.none() | st.text(max_size=40),
        "late": st.floats(0, 1e6),
        "read_ns": st.integers(0, 2**62),
        "force": st.lists(finite, min_size=3, max_size=3),
        "flags": st.integers(0, 63),
    }
)


def test_the_readme_tables_come_from_ticks_json():
    """The README's header, record and device-flag tables are what sasprobe.protocol.schemas
    renders from ticks.json; a copy that differs fails, printing the rendering to paste."""
    text = README.read_text()
    for rendered in schemas.ticks_table_markdown().split("\n\n"):
        assert rendered in text, f"protocol/README.md differs from:\n{rendered}"
    header, record, flags = readme_ticks_tables()
    layout = schemas.ticks_layout()
    assert [r[3] for r in header] == [f["name"] for f in layout["header"]["fields"]]
    assert [r[3] for r in record] == [f["name"] for f in layout["record"]["fields"]]
    assert sum(r[1] for r in header) == HEADER.size and sum(r[1] for r in record) == RECORD_SIZE
    assert flags == {f["name"]: 1 << f["bit"] for f in layout["device_flags"]}


@settings(max_examples=60, deadline=None)
@given(st.lists(tick, min_size=1, max_size=12), st.integers(0, 2**40))
def test_packed_ticks_decode_alike_by_the_codec_and_by_the_readme(ticks, first_seq):
    packer = TicksPacker()
    for k, t in enumerate(ticks):
        pose = Pose(seq=first_seq + k, publish_t_ns=1000 + k, force_N=np.array(t["force"]))
        pose.flags = t["flags"]
        packer.add(1000 + k, t["state"], t["error"], t["late"], t["read_ns"], pose)
    message = packer.take()
    block, reference = decode_ticks(message), reference_decode_ticks(message)["ticks"]
    assert len(block) == len(reference) == len(ticks) and packer.count == 0
    assert block.seq.tolist() == [first_seq + k for k in range(len(ticks))]
    for row, (t, ref) in enumerate(zip(ticks, reference)):
        assert block.errors.get(row) == ref["error"] == t["error"]
        assert ref["pose"]["seq"] == first_seq + row and ref["pose"]["flags"] == t["flags"]
        assert list(ref["pose"]["force"]) == block.pose["force_N"][row].tolist() == t["force"]
        assert ref["late_periods"] == block.device["late_periods"][row] == t["late"]
        if t["state"] is None:
            assert not block.has_state[row] and ref["device_flags"] & 1 == 0
            continue
        t_ns, position, orientation, velocity, buttons, calibrated = t["state"]
        assert block.has_state[row] and block.calibrated[row] == calibrated
        assert ref["t_ns"] == t_ns and ref["buttons"] == buttons
        for name, want in (
            ("position_mm", position),
            ("orientation", orientation),
            ("velocity_mm_s", velocity),
        ):
            got = block.device[name][row].tolist()
            assert _same(got, want) and _same(list(ref[name]), want), name  # NaN stays NaN


def _same(a: list, b: list) -> bool:
    return all(x == y or (math.isnan(x) and math.isnan(y)) for x, y in zip(a, b, strict=True))


def test_a_longer_record_of_a_later_version_is_read_up_to_this_ones_fields():
    packer = TicksPacker()
    for k in range(3):
        packer.add(k, None, "gone", 0.0, 0, Pose(seq=k))
    message = packer.take()
    header = HEADER.unpack_from(message, 0)
    records = message[HEADER.size : HEADER.size + 3 * RECORD_SIZE]
    longer = b"".join(
        records[k * RECORD_SIZE : (k + 1) * RECORD_SIZE] + b"\xab" * 8 for k in range(3)
    )
    later = (
        HEADER.pack(header[0], RECORD_SIZE + 8, 3, header[3], 0)
        + longer
        + message[HEADER.size + 3 * RECORD_SIZE :]
    )
    block = decode_ticks(later)
    assert block.seq.tolist() == [0, 1, 2] and block.errors == {0: "gone", 1: "gone", 2: "gone"}
    joined = TickBlock.join([block, decode_ticks(message)])
    assert (
        joined.seq.tolist() == [0, 1, 2, 0, 1, 2] and joined.records.dtype.itemsize == RECORD_SIZE
    )


@pytest.mark.parametrize(
    "damage",
    [
        lambda m: m[:10],  # shorter than its header
        lambda m: m[:-1],  # an error text cut
        lambda m: m + b"x",  # bytes past the error table
        lambda m: struct.pack("<H", 0) + m[2:],  # version 0
        lambda m: m[:2] + struct.pack("<H", 100) + m[4:],  # records shorter than version 1's
        lambda m: m[:4] + struct.pack("<I", 99) + m[8:],  # a count the message cannot hold
    ],
)
def test_a_damaged_message_is_refused(damage):
    packer = TicksPacker()
    packer.add(1, None, "timed out", 0.0, 0, Pose(seq=1))
    packer.add(
        2, (2, np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3), 0, True), None, 0, 0, Pose(seq=2)
    )
    message = packer.take()
    decode_ticks(message)
    with pytest.raises(TicksDecodeError):
        decode_ticks(damage(message))
