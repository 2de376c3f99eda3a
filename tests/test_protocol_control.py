"""Control messages: encoding, validation, and a real ROUTER server fed garbage."""

from __future__ import annotations

import json

import pytest
import zmq
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sasprobe.daemon.control_server import ControlServer
from sasprobe.protocol.control import (
    COMMANDS,
    MAX_REQUEST_JSON_BYTES,
    ControlReply,
    ProtocolError,
    decode_reply,
    decode_request,
    encode_reply,
    encode_request,
)


def test_round_trip_of_every_command_shape():
    frames = encode_request(
        "set", {"stiffness_n_per_mm": 0.2, "clip_planes": [[1, 0, 0, -2]]}, id=5
    )
    req = decode_request(frames)
    assert (req.cmd, req.id, req.args) == (
        "set",
        5,
        {"stiffness_n_per_mm": 0.2, "clip_planes": [[1.0, 0.0, 0.0, -2.0]]},
    )
    req = decode_request(encode_request("load", {"name": "x"}, data=b"ATOM"))
    assert req.data == b"ATOM"
    reply = decode_reply(
        encode_reply(ControlReply(ok=True, result={"a": 1}, id=3, data=b"\x00\x01"))
    )
    assert reply.ok and reply.result == {"a": 1} and reply.id == 3 and reply.data == b"\x00\x01"
    reply = decode_reply(encode_reply(ControlReply(ok=False, error="bad")))
    assert not reply.ok and reply.error == "bad"


@pytest.mark.parametrize(
    "frames, fragment",
    [
        ([b"\xff\xfe"], "UTF-8"),
        ([b"{not json"], "not valid JSON"),
        ([b"[1, 2]"], "JSON object"),
        ([b'{"cmd": 3}'], "string 'cmd'"),
        ([b'{"cmd": "fly"}'], "unknown command"),
        ([b'{"cmd": "ping", "args": []}'], "'args' must be"),
        ([b'{"cmd": "ping", "args": {"x": 1}}'], "takes no arguments"),
        ([b'{"cmd": "ping", "version": 99}'], "newer"),
        ([b'{"cmd": "set", "args": {}}'], "at least one"),
        ([b'{"cmd": "set", "args": {"stiffness_n_per_mm": "hard"}}'], "finite number"),
        ([b'{"cmd": "set", "args": {"probe_radius_A": -1}}'], "probe_radius_A"),
        ([b'{"cmd": "set", "args": {"probe_radius_A": NaN}}'], "not valid JSON"),
        ([b'{"cmd": "set", "args": {"clip_planes": [[0, 0, 0, 1]]}}'], "zero normal"),
        ([b'{"cmd": "set", "args": {"lights": {"sun": {}}}}'], "unknown light"),
        ([b'{"cmd": "set", "args": {"warp": 9}}'], "does not know"),
        ([b'{"cmd": "record_start", "args": {"path": 5}}'], "string 'path'"),
        ([b'{"cmd": "load", "args": {}}'], "string 'path'"),
        ([b'{"cmd": "get_structure", "args": {"form": "xml"}}'], "takes only 'form'"),
        ([b'{"cmd": "ping"}', b"data"], "no data frame"),
        ([b"{}", b"", b""], "1 or 2 frames"),
        ([b" " * (MAX_REQUEST_JSON_BYTES + 1)], "larger than"),
    ],
)
def test_malformed_requests_get_one_clear_line(frames, fragment):
    with pytest.raises(ProtocolError) as info:
        decode_request(frames)
    message = str(info.value)
    assert fragment in message and "\n" not in message


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(max_size=300), min_size=0, max_size=4))
def test_arbitrary_frames_never_raise_anything_but_protocol_errors(frames):
    try:
        decode_request(frames)
    except ProtocolError:
        pass


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=20),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=10), children, max_size=4)
    ),
    max_leaves=12,
)


@settings(max_examples=300, deadline=None)
@given(
    cmd=st.sampled_from(COMMANDS + ("nope",)),
    args=st.dictionaries(st.text(max_size=20), json_values, max_size=4),
)
def test_wrong_json_types_are_protocol_errors(cmd, args):
    try:
        decode_request([json.dumps({"cmd": cmd, "args": args}).encode()])
    except ProtocolError:
        pass


@pytest.fixture()
def server(tmp_path):
    context = zmq.Context()
    seen = []

    def handler(request):
        seen.append(request.cmd)
        if request.cmd == "status":
            raise RuntimeError("boom")
        return ControlReply(ok=True, result={"cmd": request.cmd})

    endpoint = f"ipc://{tmp_path}/ctl"
    srv = ControlServer(context, [endpoint], handler)
    srv.start()
    yield endpoint, context, seen, srv
    srv.stop()
    context.term()


def _request(context, endpoint, frames, kind=zmq.REQ):
    sock = context.socket(kind)
    sock.linger = 0
    sock.connect(endpoint)
    try:
        sock.send_multipart(frames)
        assert sock.poll(5000), "no reply"
        reply = sock.recv_multipart()
    finally:
        sock.close()
    if kind == zmq.DEALER and reply and reply[0] == b"":
        reply = reply[1:]
    return decode_reply(reply)


def test_server_answers_good_bad_and_failing_requests(server):
    endpoint, context, seen, srv = server
    assert _request(context, endpoint, encode_request("ping", id="a")).result == {"cmd": "ping"}
    bad = _request(context, endpoint, [b"\x00garbage"])
    assert not bad.ok and ("UTF-8" in bad.error or "JSON" in bad.error)
    failing = _request(context, endpoint, encode_request("status"))
    assert not failing.ok and "internal error" in failing.error
    via_dealer = _request(context, endpoint, encode_request("get_scene", id=9), kind=zmq.DEALER)
    assert via_dealer.ok and via_dealer.id == 9
    assert srv.errors == 2 and seen == ["ping", "status", "get_scene"]


@pytest.mark.parametrize(
    "frames",
    [
        [b'{"cmd": "explode", "id": "r1"}'],
        [b'{"cmd": "set", "args": {"stiffness_n_per_mm": "very"}, "id": "r1"}'],
        [b'{"cmd": "set", "args": {"warp": 1}, "id": "r1"}'],
        [b'{"cmd": "ping", "version": 99, "id": "r1"}'],
        [b'{"cmd": "ping", "args": [], "id": "r1"}'],
        [b'{"cmd": "ping", "id": "r1"}', b"data"],
        [b'{"cmd": "ping", "id": "r1"}', b"", b""],
        [b'{"cmd": "status", "id": "r1"}'],  # the handler fails
    ],
)
def test_every_error_reply_echoes_the_requests_id(server, frames):
    endpoint, context, _, _ = server
    for kind in (zmq.REQ, zmq.DEALER):
        reply = _request(context, endpoint, frames, kind=kind)
        assert not reply.ok and reply.id == "r1", (frames, reply)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(frames=st.lists(st.binary(max_size=200), min_size=1, max_size=3))
def test_server_replies_to_every_garbage_request(server, frames):
    endpoint, context, _, _ = server
    reply = _request(context, endpoint, frames)
    assert reply.ok or reply.error


def test_every_command_and_set_field_is_in_the_schema_and_the_readme():
    from pathlib import Path

    from sasprobe.protocol.control import SET_FIELDS
    from sasprobe.protocol.schemas import schema

    defs = schema("control")["$defs"]
    assert defs["request"]["properties"]["cmd"]["enum"] == list(COMMANDS)
    readme = (Path(__file__).resolve().parent.parent / "protocol" / "README.md").read_text()
    for cmd in COMMANDS:
        assert f"args.{cmd}" in defs and f"result.{cmd}" in defs, cmd
        assert f"| `{cmd}` |" in readme, f"command {cmd} is not in protocol/README.md's table"
    assert list(defs["args.set"]["properties"]) == list(SET_FIELDS)
    for name in SET_FIELDS:
        assert f"| `{name}` |" in readme, f"set field {name} is not in protocol/README.md's table"


@pytest.mark.parametrize(
    "request_json",
    [
        {"cmd": "ping"},
        {"cmd": "status", "args": {"reset_stats": True}, "id": "a"},
        {
            "cmd": "set",
            "args": {
                "probe_radius_A": 1.5,
                "cube_half_A": "fit",
                "lights": {"probe": {"enabled": False}},
            },
        },
        {"cmd": "view", "args": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}},
        {"cmd": "load", "args": {"path": "1crn", "keep_water": True}},
        {"cmd": "mark", "args": {"label": "site"}},
        {"cmd": "findings", "args": {"dir": "out", "probe_radius_A": 1.2}},
    ],
)
def test_requests_the_decoder_takes_follow_the_schema(request_json):
    from sasprobe.protocol.schemas import validation_errors

    decode_request([json.dumps(request_json).encode()])
    assert validation_errors("control#/$defs/request", request_json) == []


@pytest.mark.parametrize(
    "request_json",
    [
        {"cmd": "fly"},
        {"cmd": "ping", "args": {"x": 1}},
        {"cmd": "set", "args": {}},
        {"cmd": "set", "args": {"warp": 9}},
        {"cmd": "set", "args": {"probe_radius_A": 0}},
        {"cmd": "clutch", "args": {"held": "yes"}},
        {"cmd": "record_start", "args": {}},
        {"cmd": "load", "args": {"path": "a", "name": "b"}},
        {"cmd": "ping", "id": {"a": 1}},
        {"cmd": "ping", "id": "i" * 201},
        {"cmd": "view", "args": {"rotation": [[1, 0], [0, 1]]}},
    ],
)
def test_requests_the_decoder_refuses_break_the_schema(request_json):
    from sasprobe.protocol.schemas import validation_errors

    with pytest.raises(ProtocolError):
        decode_request([json.dumps(request_json).encode()])
    assert validation_errors("control#/$defs/request", request_json)
