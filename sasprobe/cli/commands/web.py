"""`sasprobe web`: follow a running daemon and show its session in any number of browsers."""

from __future__ import annotations

import argparse

from sasprobe.common.errors import UserError

HELP = "show a running daemon's session in web browsers (a page served on loopback by default)"
DEFAULT_PORT = 8765
LOOPBACK = "127.0.0.1"


def register(sub: argparse._SubParsersAction) -> None:
    from pathlib import Path

    from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT, DEFAULT_PUB_ENDPOINT

    p = sub.add_parser("web", help=HELP)
    p.add_argument(
        "--connect",
        metavar="PUB_ENDPOINT",
        help=f"the daemon's publisher (default {DEFAULT_PUB_ENDPOINT})",
    )
    p.add_argument(
        "--control",
        metavar="ENDPOINT",
        help=f"the daemon's control endpoint, for its structure (default {DEFAULT_CTL_ENDPOINT})",
    )
    p.add_argument(
        "--keys",
        type=Path,
        metavar="DIR",
        help="client keys from `sasprobe keys DIR`, for a daemon started with --keys "
        "(a loopback daemon of your own needs none)",
    )
    p.add_argument(
        "--bind",
        default=LOOPBACK,
        metavar="ADDR",
        help=f"the address the page is served on (default {LOOPBACK}: this machine only; any "
        "other needs a token, made at random unless --token gives one)",
    )
    p.add_argument(
        "--port",
        type=port_number,
        default=DEFAULT_PORT,
        metavar="N",
        help=f"the page's port (default {DEFAULT_PORT}; 0 picks a free one)",
    )
    p.add_argument(
        "--token",
        metavar="TOKEN",
        help="the secret a page's URL must carry (letters, digits, - and _, at least 16)",
    )
    p.add_argument("--keep-water", action="store_true", help="show the structure's waters")
    p.set_defaults(func=run)


def port_number(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number (0 to 65535)")
    return port


def check_token(token: str) -> str:
    import re

    if not re.fullmatch(r"[A-Za-z0-9_-]{16,128}", token):
        raise UserError("--token: use 16 to 128 letters, digits, '-' or '_'")
    return token


def daemon_keys(args: argparse.Namespace, pub: str, ctl: str, exposed: bool):
    """The client keys toward the daemon, or one clear line when it needs keys this has not."""
    from sasprobe.protocol.endpoints import parse_endpoint
    from sasprobe.protocol.security import load_client_keys, local_client_keys

    if args.keys is not None:
        return load_client_keys(args.keys)
    for endpoint in (pub, ctl):
        parsed = parse_endpoint(endpoint)
        if parsed.transport != "tcp":
            continue
        if not parsed.is_loopback:
            raise UserError(
                f"the daemon at {endpoint} wants CURVE keys: give --keys DIR "
                "(client keys from `sasprobe keys DIR`)"
            )
        if exposed and local_client_keys() is None:
            raise UserError(
                f"no CURVE keys toward the daemon at {endpoint} (a daemon of yours makes them "
                "when it starts): start the daemon first, or give --keys DIR"
            )
    return None


def run(args: argparse.Namespace) -> int:
    import asyncio
    import secrets
    import signal

    from sasprobe.molecule.packed import structure_from_served
    from sasprobe.protocol.endpoints import (
        DEFAULT_CTL_ENDPOINT,
        DEFAULT_PUB_ENDPOINT,
        parse_endpoint,
    )
    from sasprobe.protocol.follow import DaemonFollow
    from sasprobe.web.bridge import Bridge, is_loopback
    from sasprobe.web.feed import Feed

    pub = args.connect or DEFAULT_PUB_ENDPOINT
    ctl = args.control or DEFAULT_CTL_ENDPOINT
    parse_endpoint(pub), parse_endpoint(ctl)  # one clear line for a malformed one
    exposed = not is_loopback(args.bind)
    token = check_token(args.token) if args.token else None
    if exposed and token is None:
        token = secrets.token_urlsafe(18)
    keys = daemon_keys(args, pub, ctl, exposed)
    same_clock = all(parse_endpoint(e).is_loopback for e in (pub, ctl))
    keep_water = args.keep_water
    follow = DaemonFollow(
        lambda served: structure_from_served(served, keep_water), pub, ctl, keys, keep_water
    )
    bridge = Bridge(Feed(follow), pub, args.bind, args.port, token, same_clock)

    async def serve() -> None:
        try:
            url = await bridge.start()
        except OSError as exc:
            raise UserError(
                f"cannot serve on {args.bind}:{args.port} ({exc.strerror or exc})"
            ) from None
        print(url, flush=True)
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        try:
            await stop.wait()
        finally:
            await bridge.close()

    asyncio.run(serve())
    return 0
