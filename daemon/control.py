"""The control server: a ROUTER socket on its own thread, so requests never touch the loop.

Every request gets exactly one reply: the handler's result, or an error line for
anything malformed, unknown or failing (which is also logged). REQ clients and DEALER
clients both work: the reply goes back with the request's envelope.
"""

from __future__ import annotations

import logging
import threading
from typing import Callable

import zmq

from sasprobe.daemon.loop import helper_priority

from sasprobe.errors import UserError
from sasprobe.protocol.control import MAX_MESSAGE_BYTES, ProtocolError, Reply, Request, decode_request, encode_reply
from sasprobe.protocol.security import ServerKeys, bind_server_socket

log = logging.getLogger("sasprobe")

REPLY_LINGER_MS = 1000  # a reply (e.g. to `shutdown`) still goes out while the socket closes


class ControlServer:
    def __init__(self, context: zmq.Context, endpoints: list[str], handler: Callable[[Request], Reply],
                 keys: ServerKeys | None = None) -> None:
        self._handler = handler
        self._socket = context.socket(zmq.ROUTER)
        self._socket.linger = REPLY_LINGER_MS
        self._socket.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)  # larger frames drop the connection
        self.endpoints = bind_server_socket(self._socket, endpoints, keys)
        self.requests = 0
        self.errors = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sasprobe-control", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        helper_priority()
        poller = zmq.Poller()
        poller.register(self._socket, zmq.POLLIN)
        while not self._stop.is_set():
            if not poller.poll(100):
                continue
            try:
                frames = self._socket.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                continue
            envelope, body = _split_envelope(frames)
            reply = self.handle(body)
            try:
                self._socket.send_multipart(envelope + encode_reply(reply), zmq.NOBLOCK)
            except zmq.ZMQError as exc:  # the client went away; nothing to answer
                log.info("control reply not sent: %s", exc)
        self._socket.close()

    def handle(self, frames: list[bytes]) -> Reply:
        """Decode, dispatch and turn every failure into an error reply."""
        self.requests += 1
        request_id = None
        try:
            request = decode_request(frames)
            request_id = request.id
            reply = self._handler(request)
            reply.id = request.id
        except (ProtocolError, UserError, ValueError) as exc:
            reply = Reply(ok=False, error=_one_line(str(exc)) or type(exc).__name__, id=_safe_id(request_id))
        except Exception as exc:  # a bug: answer, log, keep serving
            log.exception("control request failed")
            reply = Reply(ok=False, error=f"internal error: {type(exc).__name__}: {_one_line(str(exc))}",
                          id=_safe_id(request_id))
        if not reply.ok:
            self.errors += 1
            log.warning("control: %s", reply.error)
        return reply

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        else:
            self._socket.close()


def _split_envelope(frames: list[bytes]) -> tuple[list[bytes], list[bytes]]:
    """ROUTER frames → (routing envelope to send back, request frames).

    A REQ client's envelope ends with an empty delimiter frame; a DEALER client may send
    none, in which case the envelope is just its identity.
    """
    for i in range(1, len(frames)):
        if frames[i] == b"":
            return frames[: i + 1], frames[i + 1 :]
    return frames[:1], frames[1:]


def _one_line(text: str) -> str:
    line = text.strip().splitlines()[0] if text.strip() else ""
    return line if len(line) <= 300 else line[:297] + "..."


def _safe_id(value):
    """Echo a request id only when it is plain JSON (it goes back into the reply)."""
    return value if isinstance(value, (str, int, float)) and not isinstance(value, bool) else None
