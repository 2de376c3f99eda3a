"""`sasprobe render`: draw a structure (or follow a daemon) in a window or headless."""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

from sasprobe.errors import UserError
from sasprobe.render.lighting_cli import add_lighting_arguments
from sasprobe.units import positive_float, probe_radius, size_type

log = logging.getLogger("sasprobe")

MAX_USER_PLANES = 16


def _floats(text: str, n: int, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.replace(" ", "").split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}': {what} must be {n} comma-separated numbers") from None
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"'{text}': {what} must be {n} comma-separated finite numbers")
    return values


def camera_type(text: str) -> dict:
    from sasprobe.render.camera import parse_camera

    try:
        return parse_camera(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def point_type(text: str) -> list[float]:
    return _floats(text, 3, "a point")


def direction_type(text: str) -> list[float]:
    v = _floats(text, 3, "a direction")
    if not any(v):
        raise argparse.ArgumentTypeError(f"'{text}': a direction cannot be 0,0,0")
    return v


def plane_type(text: str) -> list[float]:
    v = _floats(text, 4, "a plane a,b,c,d")
    if not any(v[:3]):
        raise argparse.ArgumentTypeError(f"'{text}': a plane needs a normal (a, b, c not all 0)")
    return v


def cube_type(text: str) -> list[float]:
    v = _floats(text, 4, "a cube X,Y,Z,HALF")
    if v[3] <= 0:
        raise argparse.ArgumentTypeError(f"'{text}': the cube's half edge must be positive")
    return v


def frames_type(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"'{text}': at least 1 frame")
    return n


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="draw a structure (or follow the daemon) in a window or headless")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--molecule", metavar="FILE", help="PDB or mmCIF file, optionally .gz (default: embedded 1CRN)")
    src.add_argument("--connect", nargs="?", const="", metavar="PUB_ENDPOINT",
                     help="follow a running daemon (default endpoint from the protocol); the structure comes from it")
    p.add_argument("--control", metavar="ENDPOINT", help="the daemon's control endpoint (with --connect)")
    p.add_argument("--headless", action="store_true", help="render offscreen through EGL (default when no display)")
    p.add_argument("--size", type=size_type, default="1280x720", metavar="WxH", help="image/window size (default 1280x720)")
    p.add_argument("--frames", type=frames_type, metavar="N", help="stop after N frames")
    p.add_argument("--seconds", type=positive_float, metavar="S", help="stop after S seconds")
    p.add_argument("--out", type=Path, metavar="FILE", help="write frames: .png (numbered when several) or .mp4")
    p.add_argument("--fps", type=positive_float, default=30.0, help="frame rate of a video --out (default 30)")
    p.add_argument("--gbuffer", type=Path, metavar="FILE.npz", help="write the last frame's G-buffer")
    p.add_argument("--camera", type=camera_type, metavar="SPEC",
                   help="'eye=X,Y,Z target=X,Y,Z up=X,Y,Z fov=DEG' (any subset; the rest is auto-fitted)")
    p.add_argument("--orbit", type=float, default=0.0, metavar="DEG", help="turn the camera DEG degrees per frame")
    p.add_argument("--spheres", choices=("quad", "sprite", "mesh"), default="quad",
                   help="atom drawing: ray-cast quads (default), point sprites (low-end), triangle meshes")
    p.add_argument("--probe", type=point_type, metavar="X,Y,Z", help="standalone: draw the probe here (Å)")
    p.add_argument("--touched", type=int, default=-1, metavar="ATOM", help="standalone: highlight this atom index")
    p.add_argument("--probe-radius", type=probe_radius, default=None, help="Å (default 1.4, or the daemon's)")
    p.add_argument("--nav-cube", type=cube_type, metavar="X,Y,Z,HALF",
                   help="standalone: navigation cube centre and half edge (Å)")
    p.add_argument("--clip", type=plane_type, action="append", default=None, metavar="A,B,C,D",
                   help="clipping plane, a·x+b·y+c·z+d >= 0 kept (repeatable)")
    p.add_argument("--probe-plane", action="store_true", help="clip with a plane through the probe facing the camera")
    p.add_argument("--light", type=direction_type, metavar="X,Y,Z", help="direction the directional light travels")
    p.add_argument("--backbone", action="store_true", help="draw the backbone trace even without a navigation cube")
    p.add_argument("--no-fxaa", action="store_true", help="skip the FXAA pass")
    p.add_argument("--keep-water", action="store_true", help="keep water molecules")
    p.add_argument("--snapshot", type=Path, metavar="FILE.png", help="headless: also write the last frame as a PNG")
    p.add_argument("--report", type=Path, metavar="FILE.json",
                   help="write frame counts, fps and (with --connect) poses received and lost as JSON at the end")
    add_lighting_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.render.app import RenderOptions, render_main

    args.clip = args.clip or []
    if len(args.clip) > MAX_USER_PLANES:
        raise UserError(f"at most {MAX_USER_PLANES} --clip planes")
    if args.frames is not None and args.seconds is not None:
        raise UserError("give --frames or --seconds, not both")
    if args.control and args.connect is None:
        raise UserError("--control needs --connect")
    if args.connect is not None and (args.probe or args.nav_cube or args.touched >= 0):
        raise UserError("--probe, --touched and --nav-cube are for standalone use; with --connect the daemon sets them")
    if args.out is not None:
        from sasprobe.render.output import check_out_path

        check_out_path(args.out, args.frames)
    if args.gbuffer is not None and args.gbuffer.suffix.lower() != ".npz":
        raise UserError(f"--gbuffer {args.gbuffer}: expected a .npz file")
    if args.snapshot is not None:
        from sasprobe.render.context import display_available
        from sasprobe.render.output import check_out_path

        if args.snapshot.suffix.lower() != ".png":
            raise UserError(f"--snapshot {args.snapshot}: expected a .png file")
        if not args.headless and display_available():
            raise UserError("--snapshot is for headless rendering (in a window, --out FILE.png saves the last frame)")
        check_out_path(args.snapshot, 1)
    return render_main(RenderOptions.from_args(args))
