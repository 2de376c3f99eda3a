"""`sasprobe demo`: the daemon with a simulated arm and a renderer following it, end to end."""

from __future__ import annotations

import argparse
from pathlib import Path

from sasprobe.cli.argtypes import positive_float
from sasprobe.cli.device_help import with_device_list
from sasprobe.cli.structure_args import MOLECULE_HELP, add_fetch_options, resolve_molecule

HELP = (
    "the daemon with the simulated arm and a renderer following it: a window, or headless a video, "
    "a snapshot and summary.json"
)


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.cli.argtypes import size_type
    from sasprobe.cli.demo import DEFAULT_SECONDS, HEADLESS_SIZE, WINDOW_SIZE, DemoOptions

    defaults = DemoOptions()

    p = sub.add_parser(
        "demo",
        help=HELP,
        **with_device_list(),
        description="Start `sasprobe daemon` (simulated arm scanning the molecule) and `sasprobe "
        "render --connect` as two processes on private ipc:// sockets. With a display: a live "
        "window until you close it. Without one (or --headless): --seconds of video, a PNG "
        "snapshot and summary.json (haptic rate and jitter, forces, contacts, renderer fps, lost "
        "poses) in --out.",
    )
    p.add_argument("--molecule", metavar="FILE|ID", help=MOLECULE_HELP)
    p.add_argument(
        "--device",
        default=defaults.device,
        help=f"the daemon's device, one of those listed below (default {defaults.device}: the "
        "simulated arm scanning the surface)",
    )
    p.add_argument("--headless", action="store_true", help="no window even when a display exists")
    p.add_argument(
        "--seconds",
        type=positive_float,
        default=None,
        metavar="S",
        help=f"how long to render (default: {DEFAULT_SECONDS:g} "
        "headless; with a window, until it is closed)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=defaults.out,
        metavar="DIR",
        help=f"where demo.mp4, snapshot.png and summary.json go (default ./{defaults.out})",
    )
    p.add_argument(
        "--size",
        type=size_type,
        default=None,
        metavar="WxH",
        help=f"frame size (default {HEADLESS_SIZE[0]}x{HEADLESS_SIZE[1]} headless, "
        f"{WINDOW_SIZE[0]}x{WINDOW_SIZE[1]} in a window)",
    )
    p.add_argument(
        "--fps",
        type=positive_float,
        default=defaults.fps,
        help=f"headless video frame rate (default {defaults.fps:g})",
    )
    p.add_argument(
        "--record",
        type=Path,
        metavar="FILE.mcap",
        help="also record the session (replay it with `sasprobe replay FILE --verify/--video`)",
    )
    p.add_argument(
        "--no-realtime",
        action="store_true",
        help="do not ask for SCHED_FIFO for the daemon's loop (by default it is asked for, and "
        "refused gracefully without the privilege)",
    )
    p.add_argument("--keep-water", action="store_true", help="keep water molecules")
    add_fetch_options(p)
    p.add_argument(
        "--keys",
        type=Path,
        metavar="DIR",
        help="CURVE keys from `sasprobe keys DIR` for both processes (the daemon's pair, the "
        "renderer's client pair), as a lab with remote renderers runs them",
    )
    p.add_argument(
        "--render-args",
        metavar="'OPTIONS'",
        help="extra `sasprobe render` options, e.g. --render-args=--no-fxaa (with the =)",
    )
    p.add_argument(
        "--daemon-args",
        metavar="'OPTIONS'",
        help="extra `sasprobe daemon` options, e.g. --daemon-args='--stiffness 0.2'",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.cli.demo import (
        RESERVED_DAEMON,
        RESERVED_RENDER,
        DemoOptions,
        run_demo,
        split_extra_args,
    )

    opts = DemoOptions(
        molecule=resolve_molecule(args, args.molecule),
        device=args.device,
        headless=args.headless,
        seconds=args.seconds,
        out=args.out,
        size=args.size,
        fps=args.fps,
        record=args.record,
        realtime=not args.no_realtime,
        keep_water=args.keep_water,
        keys=args.keys,
        render_args=split_extra_args(args.render_args, RESERVED_RENDER, "--render-args"),
        daemon_args=split_extra_args(args.daemon_args, RESERVED_DAEMON, "--daemon-args"),
    )
    return run_demo(opts)
