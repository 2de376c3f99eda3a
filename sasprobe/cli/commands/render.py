"""`sasprobe render`: draw a structure (or follow a daemon) in a window or headless.

Its options and the RenderOptions they make (the lighting options: cli/lighting_args.py);
every default shown in a help text is read from the dataclass that holds it.
"""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

from sasprobe.cli.argtypes import colour_type, positive_float, positive_int, probe_radius, size_type
from sasprobe.cli.lighting_args import add_lighting_arguments, lighting_from_args
from sasprobe.cli.structure_args import MOLECULE_HELP, add_fetch_options, resolve_molecule
from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")

MAX_USER_PLANES = 16
DEFAULT_OUT = "sasprobe-render"  # headless with no --out: .png for one frame, else .mp4

HELP = "draw a structure (or follow the daemon) in a window or headless"


def _floats(text: str, n: int, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.replace(" ", "").split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"'{text}': {what} must be {n} comma-separated numbers"
        ) from None
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(
            f"'{text}': {what} must be {n} comma-separated finite numbers"
        )
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


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS
    from sasprobe.protocol.scene import COLOR_SCHEMES
    from sasprobe.render.app import RenderOptions
    from sasprobe.render.lighting.presets import PRESET_NAMES
    from sasprobe.render.passes.spheres import SPHERE_MODES
    from sasprobe.render.workspace_view import VIEWS

    defaults = RenderOptions()
    size = f"{defaults.size[0]}x{defaults.size[1]}"
    p = sub.add_parser("render", help=HELP)
    src = p.add_mutually_exclusive_group()
    src.add_argument("--molecule", metavar="FILE|ID", help=MOLECULE_HELP)
    src.add_argument(
        "--connect",
        nargs="?",
        const="",
        metavar="PUB_ENDPOINT",
        help="follow a running daemon (default endpoint from the protocol); the structure comes "
        "from it",
    )
    p.add_argument(
        "--control", metavar="ENDPOINT", help="the daemon's control endpoint (with --connect)"
    )
    p.add_argument(
        "--keys",
        type=Path,
        metavar="DIR",
        help="with --connect: client keys from `sasprobe keys DIR`, for a daemon started with "
        "--keys "
        "(a loopback daemon of your own needs none)",
    )
    p.add_argument(
        "--headless",
        action="store_true",
        help="render offscreen through EGL (default when no display)",
    )
    p.add_argument(
        "--size",
        type=size_type,
        default=size,
        metavar="WxH",
        help=f"image/window size (default {size})",
    )
    p.add_argument("--frames", type=positive_int, metavar="N", help="stop after N frames")
    p.add_argument("--seconds", type=positive_float, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--out",
        type=Path,
        metavar="FILE|DIR",
        help="write frames: .png (numbered when several) or .mp4; in a window, a folder is where "
        "Ctrl+S "
        "(screenshot) and Ctrl+R (video) write (default: the working directory)",
    )
    p.add_argument(
        "--fps",
        type=positive_float,
        default=defaults.fps,
        help=f"frame rate of a video --out (default {defaults.fps:g})",
    )
    p.add_argument(
        "--gbuffer", type=Path, metavar="FILE.npz", help="write the last frame's G-buffer"
    )
    p.add_argument(
        "--gbuffer-dir",
        type=Path,
        metavar="DIR",
        help="headless: write every frame's G-buffer into DIR (gbuffer_0000.npz, ...)",
    )
    p.add_argument(
        "--view",
        choices=VIEWS,
        default=None,
        help="start in the workspace view (the navigation cube framed, looking along the device's "
        "-z) "
        "or the overview (the whole molecule); default: workspace with --connect, else overview "
        "(the window's Tab switches)",
    )
    p.add_argument(
        "--camera",
        type=camera_type,
        metavar="SPEC",
        help="'eye=X,Y,Z target=X,Y,Z up=X,Y,Z fov=DEG' (any subset; the rest is auto-fitted)",
    )
    p.add_argument(
        "--orbit",
        type=float,
        default=0.0,
        metavar="DEG",
        help="turn the camera DEG degrees per frame",
    )
    p.add_argument(
        "--spheres",
        choices=SPHERE_MODES,
        default=defaults.spheres,
        help=f"atom drawing: ray-cast quads, point sprites (low-end), triangle meshes "
        f"(default {defaults.spheres})",
    )
    p.add_argument(
        "--probe", type=point_type, metavar="X,Y,Z", help="standalone: draw the probe here (Å)"
    )
    p.add_argument(
        "--touched",
        type=int,
        default=-1,
        metavar="ATOM",
        help="standalone: highlight this atom index",
    )
    p.add_argument(
        "--probe-radius",
        type=probe_radius,
        default=None,
        help=f"Å (default {DEFAULT_PROBE_RADIUS:g}, or the daemon's)",
    )
    p.add_argument(
        "--nav-cube",
        type=cube_type,
        metavar="X,Y,Z,HALF",
        help="standalone: navigation cube centre and half edge (Å)",
    )
    p.add_argument(
        "--clip",
        type=plane_type,
        action="append",
        default=None,
        metavar="A,B,C,D",
        help="clipping plane, a·x+b·y+c·z+d >= 0 kept (repeatable; standalone: with --connect the "
        "daemon's planes are drawn, set them with `sasprobe set clip=A,B,C,D`)",
    )
    p.add_argument(
        "--probe-plane",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="clip with a plane square to the view axis at the probe, stepping by the probe radius "
        "(default: on in the workspace view, off in the overview)",
    )
    p.add_argument(
        "--light",
        type=direction_type,
        metavar="X,Y,Z",
        help="direction the key light travels: in the view (x right, y up, z towards you) while "
        "lights "
        "follow the camera, else in the molecule frame",
    )
    p.add_argument(
        "--light-frame",
        choices=("camera", "molecule"),
        default=defaults.light_frame,
        help="lights turn with the camera, as in every viewer, or stay fixed in the molecule "
        "frame "
        f"(default {defaults.light_frame})",
    )
    p.add_argument(
        "--color",
        choices=COLOR_SCHEMES,
        default=None,
        help="colour scheme (the window's C key; a daemon's scheme wins): element (CPK), chain "
        "(carbons "
        "by chain), chain-all (every atom by chain), polymer, residue, hydrophobicity "
        "(Kyte-Doolittle), "
        "bfactor, sas (exposed area per atom) (default: element for one polymer chain, chain for "
        "several, chain-all for several from 20000 atoms up)",
    )
    p.add_argument(
        "--preset",
        choices=PRESET_NAMES,
        default=defaults.preset,
        help=f"lighting preset (the window's I key): {', '.join(PRESET_NAMES)} (default "
        f"{defaults.preset})",
    )
    p.add_argument(
        "--background",
        type=colour_type,
        metavar="COLOUR",
        help="background colour: a name (white, black, ...), #RRGGBB or R,G,B in 0..1 (default: "
        "the preset's)",
    )
    p.add_argument(
        "--backbone",
        action="store_true",
        help="draw the backbone trace even without a navigation cube (with --connect: also when "
        "the "
        "daemon turns its cube off)",
    )
    p.add_argument("--no-fxaa", action="store_true", help="skip the FXAA pass")
    p.add_argument(
        "--overview-first",
        type=positive_float,
        metavar="S",
        help="with --connect, headless, in the workspace view: the first S seconds show the "
        "overview (the whole molecule, where the cube sits on it), then the workspace view",
    )
    p.add_argument(
        "--no-readout",
        action="store_true",
        help="with --connect, headless: pictures without the readout (haptic rate, force, "
        "touched atom, clearance) in their top-left corner",
    )
    p.add_argument(
        "--no-frame-cache",
        action="store_true",
        help="draw every frame whole (default: keep the molecule layer while only the probe moves)",
    )
    p.add_argument("--keep-water", action="store_true", help="keep water molecules")
    add_fetch_options(p)
    p.add_argument(
        "--snapshot",
        type=Path,
        metavar="FILE.png",
        help="headless: also write the last frame as a PNG",
    )
    p.add_argument(
        "--report",
        type=Path,
        metavar="FILE.json",
        help="write frame counts, fps and (with --connect) poses received and lost as JSON at the "
        "end",
    )
    add_lighting_arguments(p)
    p.set_defaults(func=run)


def render_options(args: argparse.Namespace):
    """The RenderOptions of a `sasprobe render` command line."""
    from sasprobe.render.app import RenderOptions
    from sasprobe.render.lighting.settings import DEFAULT_PROBE_RANGE

    lighting, required = lighting_from_args(args, headless=_headless(args))
    return RenderOptions(
        molecule=resolve_molecule(args, args.molecule),
        connect=args.connect,
        control=args.control,
        headless=args.headless,
        size=args.size,
        frames=args.frames,
        seconds=args.seconds,
        out=args.out,
        fps=args.fps,
        gbuffer=args.gbuffer,
        camera=args.camera,
        orbit=args.orbit,
        spheres=args.spheres,
        probe=args.probe,
        touched=args.touched,
        probe_radius=args.probe_radius,
        nav_cube=args.nav_cube,
        clip=args.clip,
        probe_plane=args.probe_plane,
        light=args.light,
        backbone=args.backbone,
        fxaa=not args.no_fxaa,
        readout=not args.no_readout,
        overview_first_s=args.overview_first,
        frame_cache=not args.no_frame_cache,
        keep_water=args.keep_water,
        lighting=lighting,
        lighting_required=required,
        probe_light_range=args.probe_light_range or DEFAULT_PROBE_RANGE,
        snapshot=args.snapshot,
        report=args.report,
        view=args.view,
        gbuffer_dir=args.gbuffer_dir,
        color=args.color,
        preset=args.preset,
        background=args.background,
        light_frame=args.light_frame,
        keys=args.keys,
    )


def _headless(args: argparse.Namespace) -> bool:
    from sasprobe.render.gl.context import display_available

    return args.headless or not display_available()


def run(args: argparse.Namespace) -> int:
    from sasprobe.render.app import render_main

    args.clip = args.clip or []
    if len(args.clip) > MAX_USER_PLANES:
        raise UserError(f"at most {MAX_USER_PLANES} --clip planes")
    if args.frames is not None and args.seconds is not None:
        raise UserError("give --frames or --seconds, not both")
    if args.control and args.connect is None:
        raise UserError("--control needs --connect")
    if args.keys and args.connect is None:
        raise UserError("--keys needs --connect")
    if args.connect is not None and (args.probe or args.nav_cube or args.touched >= 0):
        raise UserError(
            "--probe, --touched and --nav-cube are for standalone use; with --connect the daemon "
            "sets them"
        )
    if args.connect is not None and args.clip:
        raise UserError(
            "--clip is for standalone use; with --connect the clip planes are the daemon's: "
            "set them with `sasprobe set clip=A,B,C,D`"
        )
    if args.gbuffer_dir is not None:
        if not _headless(args):
            raise UserError("--gbuffer-dir is for headless rendering")
        try:
            args.gbuffer_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserError(
                f"--gbuffer-dir {args.gbuffer_dir}: cannot create ({exc.strerror or exc})"
            ) from None
    if (
        args.out is None
        and _headless(args)
        and not (args.snapshot or args.gbuffer or args.gbuffer_dir)
    ):
        single = args.seconds is None and (args.frames or 1) == 1
        args.out = Path(DEFAULT_OUT + (".png" if single else ".mp4"))  # the picture goes here
    if args.out is not None and args.out.is_dir():
        if _headless(args):
            raise UserError(
                f"--out {args.out}: a folder is where the window's Ctrl+S and Ctrl+R write; "
                "headless, give a .png or .mp4 file"
            )
    elif args.out is not None:
        from sasprobe.render.output import check_out_path

        check_out_path(args.out, args.frames)
    if args.gbuffer is not None and args.gbuffer.suffix.lower() != ".npz":
        raise UserError(f"--gbuffer {args.gbuffer}: expected a .npz file")
    if args.snapshot is not None:
        from sasprobe.render.output import check_out_path

        if args.snapshot.suffix.lower() != ".png":
            raise UserError(f"--snapshot {args.snapshot}: expected a .png file")
        if not _headless(args):
            raise UserError(
                "--snapshot is for headless rendering (in a window, --out FILE.png saves the last "
                "frame)"
            )
        check_out_path(args.snapshot, 1)
    return render_main(render_options(args))
