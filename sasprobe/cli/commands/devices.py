"""`sasprobe devices [--json] [--check DEVICE]`: what is plugged in, and does it answer."""

from __future__ import annotations

import argparse
import json
import time

from sasprobe.cli.argtypes import positive_float
from sasprobe.cli.device_help import with_device_list
from sasprobe.common.errors import UserError

CHECK_SECONDS = 1.0  # how long --check reads by default

# consecutive faults after which --check stops: a device that is gone, not one a little late
GIVE_UP_AFTER_FAULTS = 10

HELP = "list attached haptic/input devices and their --device strings"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("devices", help=HELP, **with_device_list())
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--check",
        metavar="DEVICE",
        help="open DEVICE (a --device string, schemes listed below), read it for --seconds with "
        "zero force, report",
    )
    p.add_argument(
        "--seconds",
        type=positive_float,
        default=CHECK_SECONDS,
        help=f"how long --check reads (default {CHECK_SECONDS:g})",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.check:
        return _check(args.check, args.seconds, args.json)
    from sasprobe.devices.discovery import discover

    found, notes = discover()
    if args.json:
        print(json.dumps({"devices": [f.as_dict() for f in found], "notes": notes}))
        return 0
    if not found:
        print(
            "none found (no USB serial port, no SpaceMouse, no known USB arm, no Force Dimension "
            "arm, no Inverse Service)"
        )
    for f in found:
        ids = f"{f.vendor_id:04x}:{f.product_id:04x}" if f.vendor_id is not None else "-"
        line = f"{f.transport:6} {f.path:24} {ids:9}  {f.description}"
        if f.device:
            line += f"\n       --device {f.device}" + (f"   ({f.note})" if f.note else "")
        print(line)
    for note in notes:
        print(f"note: {note}")
    return 0


def _check(spec: str, seconds: float, as_json: bool) -> int:
    import numpy as np

    from sasprobe.devices.base import DeviceFault
    from sasprobe.devices.registry import open_device

    device = open_device(spec)
    device.open()
    reads = faults = in_a_row = 0
    state = None
    first_fault = ""
    try:
        period = 1.0 / device.info.limits.nominal_rate_hz
        start = time.monotonic()
        next_tick = start
        while time.monotonic() - start < seconds:
            try:
                state = device.read()
                device.write_force(np.zeros(3))
                reads += 1
                in_a_row = 0
            except DeviceFault as exc:
                faults += 1
                in_a_row += 1
                first_fault = first_fault or str(exc)
                if in_a_row >= GIVE_UP_AFTER_FAULTS:
                    break  # unplugged or dead: a late reply now and then is only counted
            next_tick += period
            time.sleep(max(0.0, next_tick - time.monotonic()))
        elapsed = time.monotonic() - start
        info = device.info
    finally:
        device.close()
    if state is None:
        raise UserError(f"{spec} opened but never answered: {first_fault}")
    report = {
        "device": spec,
        "info": info.as_dict(),
        "reads": reads,
        "faults": faults,
        "seconds": elapsed,
        "rate_hz": reads / elapsed if elapsed > 0 else 0.0,
        "position_mm": state.position_mm.tolist(),
        "buttons": state.buttons,
        "calibrated": state.calibrated,
        "first_fault": first_fault or None,
    }
    if as_json:
        print(json.dumps(report))
        return 0
    lim = info.limits
    print(f"{info.model}  ({spec})")
    if info.serial:
        print(f"  serial     {info.serial}")
    print(
        f"  limits     {lim.max_force_n:g} N peak, {lim.continuous_force_n:g} N continuous, "
        f"{lim.max_stiffness_n_per_mm:g} N/mm, force output "
        f"{'yes' if lim.has_force_output else 'no'}"
    )
    print(
        f"  read       {reads} states in {elapsed:.2f} s "
        f"({report['rate_hz']:.0f} Hz), {faults} faults"
    )
    print(
        f"  position   ({', '.join(f'{v:.1f}' for v in state.position_mm)}) mm, buttons "
        f"{state.buttons:#x}"
    )
    calibrated = (
        "yes" if state.calibrated else "no: see the calibration steps in docs/connect-your-arm.md"
    )
    print(f"  calibrated {calibrated}")
    rejected = info.details.get("rejected_frames")
    if rejected:
        print(f"  rejected   {rejected} malformed frames")
    if first_fault:
        print(f"  fault      {first_fault}")
    return 0
