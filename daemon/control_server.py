"""The control server: a ROUTER socket on its own thread, so requests never touch the loop.

Every request gets exactly one reply: the handler's result, or an error line for
anything malformed, unknown or failing (which is also logged) — encoding the reply
included, so no request can end the thread. Should the thread end anyway (an
exception from outside Python's ordinary errors), `ensure_running()`, which the
daemon's watchdog thread calls, starts a new one on the same socket. REQ clients and
DEALER clients both work: the reply goes back with the request's envelope.

Frames are received without copying (a 256 MiB `load` is not memcpy'd under the GIL);
every frame of a message counts against the protocol's size limit.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import zmq
from sasprobe.daemon.realtime import helper_priority
from sasprobe.daemon.socket_monitor import SocketMonitor
from sasprobe.protocol.control import (
    MAX_MESSAGE_BYTES,
    ControlReply,
    ProtocolError,
    Request,
    decode_request,
    encode_reply,
)
from sasprobe.protocol.endpoints import remove_socket_files, socket_files
from sasprobe.protocol.security import ServerKeys, bind_server_socket

from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")

REPLY_LINGER_MS = 1000  # a reply (e.g. to `shutdown`) still goes out while the socket closes
POLL_MS = 100


class ControlServer:
    def __init__(
        self,
        context: zmq.Context,
        endpoints: list[str],
        handler: Callable[[Request], ControlReply],
        keys: ServerKeys | None = None,
    ) -> None:
        self._handler = handler
        self._socket = context.socket(zmq.ROUTER)
        self._socket.linger = REPLY_LINGER_MS
        # a larger frame drops the connection
        self._socket.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
        self._monitor = SocketMonitor(self._socket, "control socket", keys is not None)
        try:
            self.endpoints = bind_server_socket(self._socket, endpoints, keys)
        except BaseException:
            self._monitor.close()
            raise
        self._files = socket_files(self.endpoints)
        self.requests = 0
        self.errors = 0
        self.restarts = 0  # threads started again after one ended
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="sasprobe-control", daemon=True)
        self._thread.start()

    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def ensure_running(self) -> bool:
        """Start the thread again if it ended while the daemon still runs; True when it did."""
        if self._stop.is_set() or self._thread is None or self._thread.is_alive():
            return False
        self.restarts += 1
        log.warning(
            "control thread ended unexpectedly; started again (%d restart(s))", self.restarts
        )
        self.start()
        return True

    def _run(self) -> None:
        helper_priority()
        poller = zmq.Poller()
        poller.register(self._socket, zmq.POLLIN)
        while not self._stop.is_set():
            self._monitor.drain()
            if not poller.poll(POLL_MS):
                continue
            try:
                frames = self._socket.recv_multipart(zmq.NOBLOCK, copy=False)
            except zmq.Again:
                continue
            envelope, body = split_envelope(frames)
            reply = self.answer(body)
            try:
                self._socket.send_multipart(envelope + reply, zmq.NOBLOCK)
            except zmq.ZMQError as exc:  # the client went away; nothing to answer
                log.info("control reply not sent: %s", exc)

    def answer(self, frames: list) -> list[bytes]:
        """The encoded reply to a request's frames; never raises an ordinary exception."""
        reply = self.handle(frames)
        try:
            return encode_reply(reply)
        except Exception as exc:  # a result that is not plain JSON: a bug, answered as one
            log.exception("control reply could not be encoded")
            self.errors += 1
            return encode_reply(
                ControlReply(
                    ok=False,
                    error=f"internal error: the reply could not be encoded ({type(exc).__name__})",
                    id=reply.id,
                )
            )

    def handle(self, frames: list) -> ControlReply:
        """Decode, dispatch and turn every failure into an error reply."""
        self.requests += 1
        request_id = None
        try:
            request = decode_request(frames)
            request_id = request.id
            reply = self._handler(request)
            reply.id = request.id
        except ProtocolError as exc:
            reply = ControlReply(
                ok=False, error=one_line(str(exc)) or type(exc).__name__, id=exc.request_id
            )
        except (UserError, ValueError) as exc:
            reply = ControlReply(
                ok=False, error=one_line(str(exc)) or type(exc).__name__, id=request_id
            )
        except Exception as exc:  # a bug: answer, log, keep serving
            log.exception("control request failed")
            reply = ControlReply(
                ok=False,
                error=f"internal error: {type(exc).__name__}: {one_line(str(exc))}",
                id=request_id,
            )
        if not reply.ok:
            self.errors += 1
            log.warning("control: %s", reply.error)
        return reply

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread.is_alive():
            self._thread.join()
        self._monitor.close()
        self._socket.close()
        remove_socket_files(self._files)


def split_envelope(frames: list) -> tuple[list, list]:
    """ROUTER frames → (routing envelope to send back, request frames).

    The first frame is the peer's identity. A REQ client (or a DEALER imitating one) puts
    an empty delimiter right after it; a DEALER may send none. Only that position is a
    delimiter: an empty frame later on belongs to the request (and makes it malformed).
    """
    if len(frames) > 1 and len(frames[1]) == 0:
        return frames[:2], frames[2:]
    return frames[:1], frames[1:]


def one_line(text: str) -> str:
    line = text.strip().splitlines()[0] if text.strip() else ""
    return line if len(line) <= 300 else line[:297] + "..."
