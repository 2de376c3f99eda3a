"""`sasprobe set KEY=VALUE ...`: change a running daemon's settings over the control socket.

Each KEY=VALUE becomes a field of one control `set` (protocol/README.md), so the changes
apply together at one tick, or none of them when any value is refused; the daemon's
reply (its settings after the change) is printed. Clip planes replace the daemon's list:
`clip=A,B,C,D` once per plane, `clip=none` to remove them all. `color=SCHEME` is the
colour scheme every renderer following the daemon shows (`color=default`: each
renderer's own default).
"""

from __future__ import annotations

import argparse
import json
import math

KEYS = {  # KEY: (what it takes, the `set` field)
    "stiffness": ("N/mm", "stiffness_n_per_mm"),
    "damping": ("N·s/m", "damping_n_s_per_m"),
    "probe-radius": ("Å", "probe_radius_A"),
    "method": ("proxy|penalty", "method"),
    "cube-half": ("Å|fit|default", "cube_half_A"),
    "nav-cube": ("on|off", "nav_cube_enabled"),
    "clip": ("A,B,C,D (repeatable)|none", "clip_planes"),
    "light": ("X,Y,Z (the direction the light travels)", "lights"),
    "probe-light": ("on|off", "lights"),
    "color": ("SCHEME|default (the renderers' colour scheme)", "color_scheme"),
}


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.cli.daemon_client import add_daemon_options

    keys = ", ".join(f"{k}={what}" for k, (what, _) in KEYS.items())
    p = sub.add_parser(
        "set",
        help="change a running daemon's settings (stiffness, probe radius, clip planes, "
        "cube size, lights, colour scheme)",
        description=f"KEY=VALUE pairs, applied together or not at all. Keys: {keys}.",
    )
    p.add_argument("changes", nargs="+", metavar="KEY=VALUE")
    add_daemon_options(p)
    p.add_argument(
        "--timeout", type=float, default=5.0, metavar="S", help="seconds to wait for the reply"
    )
    p.add_argument("--json", action="store_true", help="print the daemon's reply as JSON")
    p.set_defaults(func=run)


def _numbers(text: str, n: int, key: str) -> list[float]:
    from sasprobe.common.errors import UserError

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise UserError(
            f"{key}={text}: expected " + ("a number" if n == 1 else f"{n} comma-separated numbers")
        )
    return values


def _switch(text: str, key: str) -> bool:
    from sasprobe.common.errors import UserError

    if text.lower() in ("on", "true", "yes", "1"):
        return True
    if text.lower() in ("off", "false", "no", "0"):
        return False
    raise UserError(f"{key}={text}: expected on or off")


def _color_scheme(text: str) -> str | None:
    from sasprobe.common.errors import UserError
    from sasprobe.protocol.scene import COLOR_SCHEMES

    if text.lower() == "default":
        return None
    if text.lower() not in COLOR_SCHEMES:
        raise UserError(f"color={text}: expected default or one of {', '.join(COLOR_SCHEMES)}")
    return text.lower()


def set_fields(pairs: list[str]) -> dict:
    """The `set` request's fields for KEY=VALUE pairs; UserError (one line) for a bad one."""
    from sasprobe.common.errors import UserError

    fields: dict = {}
    planes: list[list[float]] | None = None
    lights: dict = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key, value = key.strip().lower(), value.strip()
        if not sep or key not in KEYS:
            raise UserError(f"'{pair}': expected KEY=VALUE with KEY one of {', '.join(KEYS)}")
        if key in ("stiffness", "damping", "probe-radius"):
            fields[KEYS[key][1]] = _numbers(value, 1, key)[0]
        elif key == "method":
            fields["method"] = value
        elif key == "cube-half":
            fields["cube_half_A"] = (
                None
                if value == "default"
                else value
                if value == "fit"
                else _numbers(value, 1, key)[0]
            )
        elif key == "nav-cube":
            fields["nav_cube_enabled"] = _switch(value, key)
        elif key == "clip":
            planes = planes if planes is not None else []
            if value.lower() != "none":
                planes.append(_numbers(value, 4, key))
        elif key == "color":
            fields["color_scheme"] = _color_scheme(value)
        elif key == "light":
            lights.setdefault("directional", {})["direction"] = _numbers(value, 3, key)
        else:  # probe-light
            lights.setdefault("probe", {})["enabled"] = _switch(value, key)
    if planes is not None:
        fields["clip_planes"] = planes
    if lights:
        fields["lights"] = lights
    return fields


def run(args: argparse.Namespace) -> int:
    from sasprobe.cli.daemon_client import connect

    fields = set_fields(args.changes)
    with connect(args, timeout_s=args.timeout) as client:
        reply = client.set(**fields)
    if args.json:
        print(json.dumps(reply))
        return 0
    s = reply["settings"]
    cube = s["cube_half_A"]
    scheme = fields.get("color_scheme") or "each renderer's default"
    print(
        f"set at tick {reply['seq']}: stiffness {s['stiffness_n_per_mm']:g} "
        f"N/mm, damping {s['damping_n_s_per_m']:g} N·s/m, probe "
        f"{s['probe_radius_A']:g} Å, {s['method']}, cube half edge "
        + ("default" if cube is None else cube if isinstance(cube, str) else f"{cube:g} Å")
        + (f", {len(fields['clip_planes'])} clip plane(s)" if "clip_planes" in fields else "")
        + (", lights changed" if "lights" in fields else "")
        + (f", colour scheme {scheme}" if "color_scheme" in fields else "")
    )
    return 0
