"""`sasprobe daemon`: run the device daemon (fixed-rate haptic loop, publisher, control)."""

from __future__ import annotations

import argparse

from sasprobe.cli.argtypes import positive_float, probe_radius
from sasprobe.cli.device_help import with_device_list
from sasprobe.cli.structure_args import MOLECULE_HELP, add_fetch_options, resolve_molecule

HELP = "run the device daemon: haptic loop, pose/scene publisher, control server"


def speed(text: str) -> float | None:
    """--speed: a positive factor, or `max` (as fast as possible)."""
    if text.strip().lower() == "max":
        return None
    return positive_float(text)


def cube_half(text: str) -> float | str:
    """--cube-half: a positive half edge in Å, or `fit` (the whole molecule)."""
    from sasprobe.devices.workspace.start import CUBE_FIT

    return CUBE_FIT if text.strip().lower() == CUBE_FIT else positive_float(text)


def button(text: str) -> str:
    from sasprobe.daemon.buttons import parse_button

    try:
        parse_button(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def fault_spec(text: str) -> tuple[str, int, int]:
    """--inject-fault: KIND@TICK[+COUNT], checked now (a typo is one line, not a silent no-op)."""
    from sasprobe.devices.simulated.arm import FAULT_KINDS, parse_fault

    try:
        kind, tick, count = parse_fault(text, FAULT_KINDS + (LOOP_STALL, SLOW_READ))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if kind == LOOP_STALL and count > MAX_STALL_MS:
        raise argparse.ArgumentTypeError(f"fault '{text}': a stall lasts at most {MAX_STALL_MS} ms")
    return kind, tick, count


# the daemon's own: the loop sleeps COUNT ms at TICK (any device); the others are the sim arm's
LOOP_STALL = "stall"
# the daemon's own: the COUNT device reads from TICK take 4 periods each (any device)
SLOW_READ = "slow"
MAX_STALL_MS = 60_000


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.daemon.buttons import ACTIONS, DEFAULT_BUTTONS
    from sasprobe.daemon.haptics import HapticSettings
    from sasprobe.devices.base import PHANTOM_OMNI_LIMITS
    from sasprobe.devices.workspace.start import CONTEXT_FRACTION, DEFAULT_SCALE_A_PER_MM

    omni = PHANTOM_OMNI_LIMITS
    omni_half = (
        DEFAULT_SCALE_A_PER_MM
        * min(hi - lo for lo, hi in zip(omni.workspace_min_mm, omni.workspace_max_mm))
        / 2
    )
    from sasprobe.devices.base import DEFAULT_RATE_HZ
    from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT, DEFAULT_PUB_ENDPOINT
    from sasprobe.protocol.scene import COLOR_SCHEMES, HAPTIC_METHODS

    defaults = HapticSettings()

    p = sub.add_parser("daemon", help=HELP, **with_device_list())
    p.add_argument(
        "--device",
        default="sim",
        help="SCHEME[:ARG], one of the devices listed below (default sim)",
    )
    p.add_argument("--molecule", metavar="FILE|ID", help=MOLECULE_HELP)
    p.add_argument("--keep-water", action="store_true", help="keep water molecules")
    add_fetch_options(p)
    p.add_argument(
        "--color",
        choices=COLOR_SCHEMES,
        default=None,
        help="the colour scheme every renderer shows (the scene's color_scheme; default: each "
        "renderer's default by structure)",
    )
    p.add_argument(
        "--rate",
        type=positive_float,
        default=None,
        metavar="HZ",
        help=f"loop rate (default: the rate the device declares, {DEFAULT_RATE_HZ:g} for every "
        "arm; up to the fastest it declares: 4000 for Force Dimension, the Inverse3 and the "
        "simulated arm, 1000 for the others; a replay runs at its recorded rate times --speed)",
    )
    p.add_argument(
        "--speed", type=speed, default=1.0, metavar="X|max", help="replay speed factor, or max"
    )
    p.add_argument(
        "--pub",
        action="append",
        metavar="ENDPOINT",
        help="PUB endpoint for pose and scene, repeatable "
        f"(default {DEFAULT_PUB_ENDPOINT}; ipc:// too)",
    )
    p.add_argument(
        "--ctl",
        action="append",
        metavar="ENDPOINT",
        help=f"control endpoint, repeatable (default {DEFAULT_CTL_ENDPOINT})",
    )
    p.add_argument(
        "--keys",
        metavar="DIR",
        help="CURVE keys from `sasprobe keys DIR` (required beyond loopback)",
    )
    p.add_argument("--record", metavar="FILE", help="record the session to this MCAP file")
    p.add_argument(
        "--record-dir",
        metavar="DIR",
        help="let the control command record_start create "
        "recordings below this folder (default: refused)",
    )
    p.add_argument(
        "--load-dir",
        metavar="DIR",
        help="let the control command load read structure "
        "files below this folder (default: bytes only)",
    )
    p.add_argument(
        "--probe-radius",
        type=probe_radius,
        default=None,
        help=f"probe radius in Å (default {defaults.probe_radius_A:g})",
    )
    p.add_argument(
        "--method",
        choices=HAPTIC_METHODS,
        default=None,
        help=f"haptic rendering method (default {defaults.method})",
    )
    p.add_argument(
        "--stiffness",
        type=positive_float,
        default=None,
        metavar="N_PER_MM",
        help="contact stiffness (default: half the largest the arm renders stably at the loop's "
        "rate, docs/haptics.md#default-stiffness)",
    )
    p.add_argument(
        "--damping",
        type=float,
        default=None,
        metavar="N_S_PER_M",
        help=f"contact damping (default {defaults.damping_n_s_per_m:g})",
    )
    p.add_argument(
        "--cube-half",
        type=cube_half,
        default=None,
        metavar="ANGSTROM|fit",
        help=f"navigation-cube half edge in Å, or fit (the whole molecule); default "
        f"{DEFAULT_SCALE_A_PER_MM:g} Å per mm of the device's workspace ({omni_half:g} Å on an "
        f"Omni-class arm), at most {CONTEXT_FRACTION:g} of the molecule's smallest width",
    )
    p.add_argument(
        "--button",
        action="append",
        type=button,
        metavar="ACTION=N",
        help=f"which device button does what (repeatable; actions {', '.join(ACTIONS)}; default "
        + ", ".join(f"{a}={i}" for a, i in DEFAULT_BUTTONS.items())
        + ")",
    )
    p.add_argument(
        "--no-realtime",
        action="store_true",
        help="do not ask for SCHED_FIFO (by default the "
        "loop asks for it, and warns when it is refused)",
    )
    p.add_argument(
        "--inject-fault",
        action="append",
        type=fault_spec,
        metavar="KIND@TICK[+COUNT]",
        help="to try the watchdogs: raise, nan or disconnect at a tick (simulated arm), "
        "stall@TICK+MS (the loop sleeps MS ms) or slow@TICK+N (N device reads take 4 periods "
        "each; any device); repeatable",
    )
    p.add_argument(
        "--inject-button",
        action="append",
        metavar="BUTTON@TICK+COUNT",
        help="simulated arm only: hold a button down from a tick for COUNT ticks (repeatable)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated arm")
    p.add_argument(
        "--seconds", type=positive_float, default=None, metavar="S", help="stop after S seconds"
    )
    p.add_argument("--report", metavar="FILE", help="write the exit report (JSON) here")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.daemon.service import Daemon, DaemonConfig
    from sasprobe.protocol.endpoints import DEFAULT_CTL_ENDPOINT, DEFAULT_PUB_ENDPOINT

    settings = {
        key: value
        for key, value in (
            ("probe_radius_A", args.probe_radius),
            ("method", args.method),
            ("stiffness_n_per_mm", args.stiffness),
            ("damping_n_s_per_m", args.damping),
            ("cube_half_A", args.cube_half),
        )
        if value is not None
    }
    faults = args.inject_fault or []
    device_faults = [
        f"{kind}@{tick}+{count}"
        for kind, tick, count in faults
        if kind not in (LOOP_STALL, SLOW_READ)
    ]
    if device_faults and args.device.split(":", 1)[0].strip().lower() != "sim":
        from sasprobe.common.errors import UserError

        raise UserError(
            f"--inject-fault {device_faults[0]}: only the simulated arm (--device sim...) takes "
            f"raise, nan and disconnect faults; stall@TICK+MS and slow@TICK+N work on any device"
        )
    config = DaemonConfig(
        device=args.device,
        molecule=resolve_molecule(args, args.molecule),
        keep_water=args.keep_water,
        rate_hz=args.rate,
        pub=args.pub or [DEFAULT_PUB_ENDPOINT],
        ctl=args.ctl or [DEFAULT_CTL_ENDPOINT],
        record=args.record,
        record_dir=args.record_dir,
        load_dir=args.load_dir,
        keys=args.keys,
        settings=settings,
        speed=args.speed,
        seed=args.seed,
        report=args.report,
        max_seconds=args.seconds,
        realtime=not args.no_realtime,
        faults=device_faults,
        loop_stalls=[(tick, ms / 1000.0) for kind, tick, ms in faults if kind == LOOP_STALL],
        slow_reads=[(tick, count) for kind, tick, count in faults if kind == SLOW_READ],
        buttons=args.button or [],
        button_presses=args.inject_button or [],
        color_scheme=args.color,
    )
    try:
        daemon = Daemon(config)
    except ValueError as exc:  # a haptic setting the device cannot render
        from sasprobe.common.errors import UserError

        raise UserError(str(exc)) from None
    return daemon.run()
