"""Nothing a client sends can end the control server: the request limits by name, replies that
cannot be encoded, a killed control thread, and a fuzz of the real handlers (in-process)."""

from __future__ import annotations

import ctypes
import json
import logging
import math
import sys
import threading
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st
from sasprobe.daemon.control_server import ControlServer, split_envelope
from sasprobe.daemon.service import Daemon, DaemonConfig
from sasprobe.protocol.client import ControlClient
from sasprobe.protocol.control import (
    COMMANDS,
    MAX_MESSAGE_BYTES,
    MAX_NESTING,
    ControlReply,
    ProtocolError,
    decode_reply,
    decode_request,
    encode_request,
)

from tests.support.bounded import join
from tests.support.fuzz import fuzz_settings


class _Sized:
    """A frame that only has a length: enough for the size check, without allocating it."""

    def __init__(self, n: int) -> None:
        self.n = n

    def __len__(self) -> int:
        return self.n


@pytest.mark.parametrize(
    "frames, fragment",
    [
        ([b'{"cmd": "ping", "id": 1e400}'], "not finite"),
        ([b'{"cmd": "ping", "id": -1e400}'], "not finite"),
        ([b'{"cmd": "ping", "id": ' + b"9" * 401 + b"}"], "401 digits"),
        ([b'{"cmd": "set", "args": {"stiffness_n_per_mm": ' + b"1" * 30 + b"}}"], "30 digits"),
        ([b'{"cmd": "ping", "id": ' + b"[" * 20000 + b"]" * 20000 + b"}"], "deeper than"),
        (
            [
                b'{"cmd": "ping", "id": '
                + b"[" * (MAX_NESTING + 1)
                + b"]" * (MAX_NESTING + 1)
                + b"}"
            ],
            "deeper than",
        ),
        ([b"{}", _Sized(MAX_MESSAGE_BYTES // 2), _Sized(MAX_MESSAGE_BYTES // 2)], "in 3 frames"),
        ([b'{"cmd": "load"}', _Sized(MAX_MESSAGE_BYTES)], "larger than"),
        ([b'{"cmd": "load", "args": {"name": "' + b"n" * 300 + b'"}}', b"ATOM"], "at most 200"),
    ],
)
def test_limits_are_refused_by_name(frames, fragment):
    with pytest.raises(ProtocolError) as info:
        decode_request(frames)
    assert fragment in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    "raw_id", [b'{"a": 1}', b"[1]", b"true", b"null", b'"' + b"i" * 201 + b'"']
)
def test_an_id_that_is_not_a_short_string_or_a_number_is_refused(raw_id):
    with pytest.raises(
        ProtocolError, match="'id' must be a string of at most 200 characters or a number"
    ) as info:
        decode_request([b'{"cmd": "ping", "id": ' + raw_id + b"}"])
    assert info.value.request_id is None  # nothing to echo
    assert decode_request([b'{"cmd": "ping", "id": "' + b"i" * 200 + b'"}']).id == "i" * 200


DEEP = b"[" * 20000 + b"]" * 20000  # far deeper than Python's parser recurses


@pytest.mark.parametrize(
    "frame, request_id",
    [
        (b'{"cmd": "ping", "id": "n", "args": {"x": 1e400}}', "n"),  # a limit: the id was readable
        (b'{"cmd": "set", "id": 7, "args": {"stiffness_n_per_mm": ' + b"1" * 30 + b"}}", 7),
        (b'{"id": "deep", "cmd": "ping", "args": ' + DEEP + b"}", "deep"),
        (
            b'{"id": -2.5, "cmd": "ping", "args": '
            + b"[" * (MAX_NESTING + 1)
            + b"]" * (MAX_NESTING + 1)
            + b"}",
            -2.5,
        ),
        (b'{"cmd": "nope", "id": "u"}', "u"),
        (b'{"cmd": "ping", "id": 1e400}', None),  # the id itself is not valid
        (b'{"cmd": "ping", "id": ' + b"9" * 19 + b"}", None),
        (b'{"cmd": "ping", "id": "n", "args": [1e400, ]}', None),  # not JSON
        (b'{"cmd": "ping", "id": "n", "args": ' + DEEP + b", }", None),
        (b'{"cmd": "ping", "id": "n", "args": {"x": NaN}}', None),
        (b'{"cmd": "ping", "id": "n"} {}', None),
        (b'\xff{"cmd": "ping", "id": "n"}', None),
    ],
)
def test_an_error_reply_carries_the_id_wherever_it_can_be_read(frame, request_id):
    with pytest.raises(ProtocolError) as info:
        decode_request([frame])
    assert info.value.request_id == request_id and type(info.value.request_id) is type(request_id)


def test_a_dealer_request_with_an_empty_frame_is_framed_correctly():
    # [identity, json, empty]: the empty frame belongs to the request, not to the envelope
    envelope, body = split_envelope([b"id", b'{"cmd":"ping"}', b""])
    assert envelope == [b"id"] and body == [b'{"cmd":"ping"}', b""]
    assert split_envelope([b"id", b"", b'{"cmd":"ping"}']) == ([b"id", b""], [b'{"cmd":"ping"}'])


def test_a_reply_that_cannot_be_encoded_is_an_error_reply(tmp_path):
    import zmq

    context = zmq.Context()
    server = ControlServer(
        context,
        [f"ipc://{tmp_path}/c"],
        lambda r: ControlReply(ok=True, result={"x": float("inf")}),
    )
    try:
        reply = decode_reply(server.answer(encode_request("ping", id=4)))
        assert not reply.ok and "could not be encoded" in reply.error and reply.id == 4
    finally:
        server.stop()
        context.term()


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """A real daemon (simulated arm) in this process, its loop on a thread of its own; the
    tests call its control server's request path directly."""
    folder = tmp_path_factory.mktemp("fuzz")
    daemon = Daemon(
        DaemonConfig(pub=[f"ipc://{folder}/p"], ctl=[f"ipc://{folder}/c"], realtime=False, spin_s=0)
    )
    switch = sys.getswitchinterval()
    sys.setswitchinterval(
        1e-4
    )  # as Daemon.run() does: the loop and the requests share the GIL finely
    logging.getLogger("sasprobe").setLevel(
        logging.ERROR
    )  # one warning per refused request otherwise
    loop = threading.Thread(target=daemon.loop.run, name="loop", daemon=True)
    loop.start()
    yield daemon
    sys.setswitchinterval(switch)
    daemon.request_stop("test over")
    loop.join(10)
    daemon._shutdown()


# Requests assembled from fragments: every JSON type, the refused numbers, deep nesting, and
# the values each command takes; and raw frames. Hypothesis supplies the random source of
# each batch of 50 (drawing every message through strategies costs ~1 ms a message, which
# 10,000 messages cannot afford); a failing batch is reported and replayed from its seed.
VALUES = [
    "null",
    "true",
    "false",
    "0",
    "-1",
    "0.3",
    "1.4",
    "7",
    "1e400",
    "-1e400",
    "1" * 30,
    "NaN",
    "Infinity",
    '""',
    '"x"',
    '"proxy"',
    '"penalty"',
    '"../../etc/passwd"',
    '"/dev/zero"',
    "[]",
    "{}",
    "[1, 2]",
    "[[0, 0, 1, -5]]",
    "[[0, 0, 0, 1]]",
    '{"probe": {"enabled": false}}',
    '{"sun": {}}',
    '{"directional": {"direction": [0, 0, 0]}}',
    "[" * 40 + "]" * 40,
    '{"a": ' * 20 + "1" + "}" * 20,
]
KEYS = [
    "path",
    "name",
    "keep_water",
    "reset_stats",
    "probe_radius_A",
    "stiffness_n_per_mm",
    "damping_n_s_per_m",
    "method",
    "cube_half_A",
    "nav_cube_enabled",
    "clip_planes",
    "lights",
    "x",
]
CMDS = [f'"{c}"' for c in COMMANDS if c != "shutdown"] + ['"nope"', '""', "3", "null"]
DATA = [[], [], [b""], [b"ATOM"], [b"\x1f\x8b junk"], [b"x", b"y"]]
FUZZ_BATCH = 50


def random_message(rng) -> list[bytes]:
    if rng.random() < 0.2:
        return [rng.randbytes(rng.randrange(40)) for _ in range(rng.randrange(4))]
    pairs = [(rng.choice(KEYS), rng.choice(VALUES)) for _ in range(rng.randrange(4))]
    args = (
        "{" + ", ".join(f'"{k}": {v}' for k, v in pairs) + "}"
        if rng.random() < 0.8
        else rng.choice(VALUES)
    )
    text = f'{{"cmd": {rng.choice(CMDS)}, "args": {args}'
    if rng.random() < 0.5:
        text += f', "id": {rng.choice(VALUES)}'
    if rng.random() < 0.2:
        text += f', "version": {rng.choice(["0", "1", "2", "1.5", "true"])}'
    return [(text + "}").encode(), *rng.choice(DATA)]


def readable_id(frame: bytes):
    """protocol/README.md's rule, read with Python's own parser: the id a reply must carry
    when the first frame is one JSON object (whatever its numbers and nesting) whose `id` is
    valid (a string of at most 200 characters, a finite number, an integer of at most 18
    digits); None otherwise."""
    try:
        obj = json.loads(frame.decode("utf-8"), parse_constant=_not_json)
    except (ValueError, RecursionError):
        return None
    value = obj.get("id") if isinstance(obj, dict) else None
    if isinstance(value, str):
        return value if len(value) <= 200 else None
    if isinstance(value, int) and not isinstance(value, bool):
        return value if len(str(abs(value))) <= 18 else None
    return value if isinstance(value, float) and math.isfinite(value) else None


def _not_json(name: str):
    raise ValueError(name)


@fuzz_settings(200, inputs_per_example=FUZZ_BATCH)
@given(rng=st.randoms(use_true_random=False))
def test_fuzzed_requests_get_named_errors_from_the_real_handlers(live, rng):
    """200 batches of 50 (SASPROBE_FUZZ=N: N messages, tests/support/fuzz.py): 10,000
    messages through the daemon's real request path, each reply carrying the request's id
    wherever it can be read."""
    for _ in range(FUZZ_BATCH):
        frames = random_message(rng)
        reply = decode_reply(live.control.answer(frames))
        assert reply.ok or (
            reply.error and "\n" not in reply.error and not reply.error.startswith("internal")
        ), (frames, reply.error)
        assert reply.id == (readable_id(frames[0]) if frames else None), (frames, reply)
        if reply.ok:  # only a well-formed request of a known command succeeds
            assert json.loads(frames[0])["cmd"] in COMMANDS
            live.fuzz_ok = getattr(live, "fuzz_ok", 0) + 1


def test_the_loop_and_the_server_outlive_the_fuzz(live):
    assert live.loop.stop_reason is None and live.control.errors > 5000 and live.fuzz_ok > 20
    ticks = live.loop.stats.total_ticks
    time.sleep(0.05)
    assert live.loop.stats.total_ticks > ticks, "the loop stopped"


def _kill_thread(thread: threading.Thread) -> None:
    """Raise SystemExit inside another thread: what no `except Exception` can stop."""
    done = ctypes.pythonapi.PyThreadState_SetAsyncExc(
        ctypes.c_ulong(thread.ident), ctypes.py_object(SystemExit)
    )
    assert done == 1


def test_a_killed_control_thread_is_started_again(live):
    # (waits for the condition, each within 30 s: a busy machine runs these threads late)
    with ControlClient(live.config.ctl[0], timeout_s=30.0) as client:
        live.control.start()  # this fixture called answer() directly so far
        assert client.ping()["pong"]
        _kill_thread(live.control._thread)
        join(live.control._thread, 30.0)
        assert not live.control.alive()
        assert client.ping()["pong"]  # the watchdog thread's supervision restarted it
        assert live.control.restarts == 1
