"""`sasprobe web`'s server: the page's files over HTTP and the session over WebSocket, on one
port, with the `websockets` package (no HTTP parsed here).

Each page is sent the bridge's conventions, the structure and its colours (packets), the
scene, whether the daemon is there, and poses: the newest pose whenever the page says it drew
the last one (`{"drawn": seq}`, the only message a page sends), so poses reach each page at
the rate it draws and nothing queues for a slow one. Every page has its own sending task: a
page that stops reading blocks only that task, never the daemon, the follow thread or the
other pages. Nothing a page sends reaches the daemon: the bridge's only requests to it are
the structure fetches of protocol/follow.py.

Who may read: on loopback, pages from this machine; elsewhere only with the token, which is
the first segment of every path (`/TOKEN/`, `/TOKEN/ws`), so a page's own relative URLs carry
it. A request without the right token, for a file that is not the page's, or naming a Host
the bridge does not serve under (a loopback bridge answers only to loopback names, which
stops DNS rebinding), is refused; a WebSocket upgrade whose Origin is not the page's own (a
page of another site reading the session through the user's browser) is refused too.

The latency a page shows (and `sasprobe bench web` reports) runs from the daemon publishing a
pose to the bridge hearing that a page drew it; it is measured only when the daemon shares
the bridge's clock (a loopback or ipc endpoint).
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
import time
from collections import deque
from urllib.parse import urlsplit

from sasprobe.web.feed import Feed
from sasprobe.web.packets import hello
from sasprobe.web.page_files import LIVE_PAGE, REPLAY_PAGE, content_type, page_files, script_hash

log = logging.getLogger("sasprobe")

LATENCY_WINDOW = 1000  # drawn poses a page's latency percentiles cover
STATS_EVERY_S = 0.25  # a page's percentiles are worked out again this often
SENT_KEPT = 64  # poses a page was sent whose publish times are kept for its acks
MAX_MESSAGE = 256  # bytes: a page sends only `{"drawn": seq}`


def is_loopback(host: str) -> bool:
    """Whether a host (a name, or an address, IPv6 in brackets or not) is this machine only."""
    import ipaddress

    host = host.strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def percentile(values, q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


class Page:
    """One connected page: what it has been sent and what it drew."""

    def __init__(self, ws) -> None:
        self.ws = ws
        self.wake = asyncio.Event()
        self.wants_pose = True
        self.sent_seq: int | None = None
        self.sent: dict[int, int] = {}  # seq -> publish_t_ns of the last poses sent
        self.latencies: deque[float] = deque(maxlen=LATENCY_WINDOW)  # ms
        self.packets_sha: str | None = None
        self.colors_key: tuple | None = None
        self.scene_key: tuple | None = None
        self.connected: bool | None = None
        self.stats: dict = {}
        self.stats_at = -1.0


class Bridge:
    def __init__(
        self,
        feed: Feed,
        pub: str,
        host: str,
        port: int,
        token: str | None,
        same_clock: bool,
    ) -> None:
        self.feed = feed
        feed.changed = self._changed_threadsafe
        self.pub = pub
        self.host = host
        self.port = port
        self.token = token
        self.same_clock = same_clock  # the daemon's publish times are on this clock
        self.pages: set[Page] = set()
        self.loopback = is_loopback(host)
        self.prefix = f"/{token}/" if token else "/"
        self.hello = json.dumps(hello())
        files = page_files()
        self.files = {name: data for name, data in files.items() if name != REPLAY_PAGE}
        self.import_map_hash = script_hash(files[LIVE_PAGE])
        self._loop: asyncio.AbstractEventLoop | None = None
        self.server = None

    # ------------------------------------------------------------ serving
    async def start(self) -> str:
        """Start serving; returns the page's URL (with the token when there is one)."""
        from websockets.asyncio.server import serve

        self._loop = asyncio.get_running_loop()
        self.server = await serve(
            self._session,
            self.host,
            self.port,
            process_request=self._request,
            compression=None,
            max_size=MAX_MESSAGE,
            max_queue=4,
            logger=logging.getLogger("sasprobe.web.websockets"),
        )
        self.port = self.server.sockets[0].getsockname()[1]
        self.feed.start()
        return self.url()

    def url(self) -> str:
        host = self.host
        if host in ("0.0.0.0", "::", ""):
            import socket

            host = socket.gethostname()
        if ":" in host:
            host = f"[{host}]"
        return f"http://{host}:{self.port}{self.prefix}"

    async def close(self) -> None:
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()
        await asyncio.to_thread(self.feed.stop)

    def _changed_threadsafe(self) -> None:
        loop = self._loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(self._wake_pages)

    def _wake_pages(self) -> None:
        for page in self.pages:
            page.wake.set()

    # ------------------------------------------------------------ HTTP
    def _refuse(self, connection, status: int, why: str):
        log.info("refused %s: %s", connection.remote_address, why)
        return connection.respond(status, why + "\n")

    def _request(self, connection, request):
        """Serve a page file, refuse, or let a WebSocket upgrade go on (None)."""
        headers = request.headers
        host = headers.get("Host", "")
        if self.loopback and not is_loopback(_host_name(host)):
            return self._refuse(connection, 403, f"not served under the host name {host!r}")
        path = urlsplit(request.path).path
        if self.token and path == self.prefix[:-1]:
            response = connection.respond(308, "")
            response.headers["Location"] = self.prefix
            return response
        if not _matches(path, self.prefix):
            return self._refuse(connection, 403, "no access without the page's token")
        name = path[len(self.prefix) :]
        if name == "ws":
            origin = headers.get("Origin")
            if origin is not None and origin != f"http://{host}":
                return self._refuse(connection, 403, f"WebSocket from a foreign origin {origin}")
            return None
        name = name or LIVE_PAGE
        data = self.files.get(name)
        if data is None:
            return self._refuse(connection, 404, "not one of the page's files")
        csp = (
            f"default-src 'none'; script-src 'self' {self.import_map_hash}; style-src 'self'; "
            f"connect-src 'self' ws://{host}; img-src 'self'; base-uri 'none'; "
            "form-action 'none'; frame-ancestors 'none'"
        )
        response = connection.respond(200, "")
        response.body = data
        h = response.headers
        for key, value in (
            ("Content-Length", str(len(data))),
            ("Content-Type", content_type(name)),
            ("Cache-Control", "no-store"),
            ("X-Content-Type-Options", "nosniff"),
            ("Referrer-Policy", "no-referrer"),
            ("Content-Security-Policy", csp),
        ):
            if key in h:
                del h[key]
            h[key] = value
        return response

    # ------------------------------------------------------------ WebSocket
    async def _session(self, ws) -> None:
        page = Page(ws)
        self.pages.add(page)
        sender = asyncio.create_task(self._send(page))
        try:
            async for message in ws:
                self._take(page, message)
        except Exception as exc:  # noqa: BLE001 - a page that breaks off costs only itself
            log.debug("page %s: %s", ws.remote_address, exc)
        finally:
            self.pages.discard(page)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await sender

    def _take(self, page: Page, message) -> None:
        """A page's `{"drawn": seq}`: it drew that pose and wants the next; the rest is dropped."""
        seq = None
        if isinstance(message, str):
            with contextlib.suppress(ValueError):
                value = json.loads(message)
                if isinstance(value, dict) and type(value.get("drawn")) is int:
                    seq = value["drawn"]
        if seq is None:
            return
        published = page.sent.get(seq)
        if published is not None and self.same_clock:
            page.latencies.append((time.monotonic_ns() - published) / 1e6)
        page.wants_pose = True
        page.wake.set()

    async def _send(self, page: Page) -> None:
        ws = page.ws
        feed = self.feed
        await ws.send(self.hello)
        while True:
            packets = feed.packets
            if packets is not None and packets.sha256 != page.packets_sha:
                await ws.send(packets.structure)
                page.packets_sha, page.colors_key = packets.sha256, None
            if packets is not None and packets.colors_key != page.colors_key:
                await ws.send(packets.colors)
                page.colors_key = packets.colors_key
            if feed.scene_json is not None and feed.scene_key != page.scene_key:
                page.scene_key = feed.scene_key
                await ws.send(feed.scene_json)
            if feed.connected != page.connected:
                page.connected = feed.connected
                await ws.send(
                    json.dumps(
                        {"type": "daemon", "connected": page.connected, "endpoint": self.pub}
                    )
                )
            if page.wants_pose:
                latest = feed.latest
                if latest is not None and latest[0].seq != page.sent_seq:
                    page.wants_pose = False
                    await ws.send(self._pose_message(page, *latest))
                else:
                    feed.pose_wanted.set()
            await page.wake.wait()
            page.wake.clear()

    def _pose_message(self, page: Page, pose, label: str | None) -> str:
        page.sent_seq = pose.seq
        page.sent[pose.seq] = pose.publish_t_ns
        if len(page.sent) > SENT_KEPT:
            del page.sent[next(iter(page.sent))]
        now = time.monotonic()
        if now - page.stats_at >= STATS_EVERY_S:
            page.stats_at = now
            page.stats = {"rate_hz": self.feed.rate_hz}
            if page.latencies:
                page.stats["latency_ms"] = [
                    percentile(page.latencies, 0.5),
                    percentile(page.latencies, 0.95),
                ]
        stats = page.stats
        return json.dumps(
            {
                "type": "pose",
                "seq": pose.seq,
                "proxy": list(pose.proxy_A),
                "goal": list(pose.goal_A),
                "force": list(pose.force_N),
                "cube": [*pose.cube_center_A, pose.cube_half_A],
                "touched": pose.touched_atom,
                "flags": pose.flags,
                "label": label,
                "stats": stats,
            }
        )


def _host_name(header: str) -> str:
    """The name or address of a Host header, without its port."""
    if header.startswith("["):
        return header[1 : header.find("]")]
    return header.partition(":")[0]


def _matches(path: str, prefix: str) -> bool:
    """Whether a path lies under the prefix, its token compared in constant time."""
    head = path[: len(prefix)]
    return len(head) == len(prefix) and hmac.compare_digest(head.encode(), prefix.encode())
