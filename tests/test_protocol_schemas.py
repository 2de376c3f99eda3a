"""protocol/schemas/: valid JSON Schema 2020-12, and standalone as a recording embeds them."""

from __future__ import annotations

import pytest
from jsonschema import Draft202012Validator
from sasprobe.protocol import schemas

from tests.support.bounded import join
from tests.support.scene import example_scene


@pytest.mark.parametrize("name", [*schemas.SCHEMA_FILES, "pose"])
def test_every_schema_is_draft_2020_12_with_its_id(name):
    schema = schemas.schema(name)
    Draft202012Validator.check_schema(schema)
    assert (
        schema["$schema"] == schemas.DIALECT
        and schema["$id"] == schemas.URN + name
        and schema["title"]
    )


@pytest.mark.parametrize("name", [*schemas.SCHEMA_FILES, "pose"])
def test_a_bundled_schema_stands_alone(name):
    """What a recording carries resolves every reference without the other files."""
    bundled = schemas.bundled(name)
    Draft202012Validator.check_schema(bundled)
    refs: set = set()
    schemas._references(bundled, refs)
    assert refs - {name} <= {key[len(schemas.URN) :] for key in bundled.get("$defs", {})}


def test_a_bundled_schema_validates_as_the_registry_does():
    control = Draft202012Validator(schemas.bundled("control-record"))
    mark = example_scene()["marks"][0]
    assert control.is_valid({"seq": 3, "cmd": "mark", "args": mark})
    assert not control.is_valid({"seq": 3, "cmd": "mark", "args": {**mark, "source": "nose"}})
    assert schemas.validation_errors(
        "control-record", {"seq": 3, "cmd": "mark", "args": {**mark, "source": "nose"}}
    )


def test_every_recording_a_test_reads_is_checked(tmp_path):
    """tests/conftest.py checks each record as sasprobe's reader hands it out, whichever
    module imported the reader: an undocumented command fails the test that reads it."""
    from sasprobe.daemon.recording.replay import open_session
    from sasprobe.daemon.recording.writer import Recorder
    from sasprobe.protocol.recording import iter_items, summarize

    path = tmp_path / "bad.mcap"
    recorder = Recorder(path)
    recorder.offer_json("control", 1, {"seq": 0, "cmd": "explode", "args": {}})
    recorder.close()
    for read in (
        lambda: list(iter_items(path)),
        lambda: summarize(path),
        lambda: open_session(path),
    ):
        with pytest.raises(pytest.fail.Exception, match="'explode' is not one of"):
            read()


def test_a_reply_is_checked_as_the_frames_the_client_received(tmp_path):
    """tests/conftest.py checks each reply's JSON frame as it came off the socket: a key the
    schema does not list fails, though sasprobe's decoder would drop it."""
    import json
    import threading

    import zmq
    from sasprobe.protocol.client import ControlClient

    router = zmq.Context.instance().socket(zmq.ROUTER)
    router.linger = 0
    endpoint = f"ipc://{tmp_path}/ctl"
    router.bind(endpoint)

    def answer(extra: dict) -> None:
        if not router.poll(20_000):  # no request came: the client failed (its error is the test's)
            return
        identity, empty, request = router.recv_multipart()
        reply = {
            "version": 1,
            "ok": True,
            "result": {"pong": True, "t_ns": 1, "daemon_version": "0"},
            "id": json.loads(request)["id"],
            **extra,
        }
        router.send_multipart([identity, empty, json.dumps(reply).encode()])

    try:
        with ControlClient(endpoint, timeout_s=10) as client:
            for extra in ({}, {"surprise": 1}):
                server = threading.Thread(target=answer, args=(extra,))
                server.start()
                try:
                    if extra:
                        with pytest.raises(AssertionError, match="surprise"):
                            client.request("ping")
                    else:
                        assert client.request("ping").result["pong"]
                finally:
                    join(server)
    finally:
        router.close()
