"""The Inverse Service's simulation channel, 3.x JSON format: messages out, state in, and the
one mapping from Haply's frame to sasprobe's.

Facts (docs.haply.co/inverseSDK/service/, pages named in devices/README.md): on connect
the service sends one inventory (`session_id`; per device `device_id`, `config`, `state`,
`status`), then exactly one state update per client message and nothing else. A device
command is per tick: `{"inverse3": [{"device_id": ID, "commands": {"set_cursor_force":
{"vector": {x, y, z}}}}]}` in newtons; a device not commanded goes idle. The session's
first message may carry `session.configure.profile.name` and, per device,
`configure.preset`; `arm_front_centered` puts the origin at the workspace centre.
`state.cursor_position` is in metres, `cursor_velocity` in m/s, in Haply's right-handed
frame: +X right, +Y forward (away from the user), +Z up. A wireless VerseGrip reports
`state.buttons` and `state.orientation` (a quaternion x, y, z, w).

sasprobe's device frame is x right, y up, z toward the user: X = x, Y = z, Z = −y (in mm),
a rotation (−90° about x), so forces map back with its transpose and orientations as
P·R·Pᵀ.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np
from sasprobe.devices.kinematics import quaternion_from_matrix

DEFAULT_URL = "ws://localhost:10001"
PROFILE_NAME = "org.sasprobe:daemon"
PRESET = "arm_front_centered"
GRIP_BUTTONS = ("a", "b", "c")  # → bits 0, 1, 2

HAPLY_TO_DEVICE = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


class FormatError(ValueError):
    """A message that is not in the Inverse Service's 3.x format (the text says what is wrong)."""


@dataclass
class Reading:
    position_mm: np.ndarray
    velocity_mm_s: np.ndarray
    calibrated: bool
    buttons: int = 0
    orientation: np.ndarray | None = None  # the VerseGrip's, in the device frame; None without one


def position_mm(haply_m) -> np.ndarray:
    return HAPLY_TO_DEVICE @ np.asarray(haply_m, dtype=float) * 1000.0


def haply_force(device_force_n) -> np.ndarray:
    return HAPLY_TO_DEVICE.T @ np.asarray(device_force_n, dtype=float)


def orientation(haply_xyzw) -> np.ndarray:
    """A Haply quaternion (x, y, z, w) as the device frame's (w, x, y, z)."""
    x, y, z, w = (float(v) for v in haply_xyzw)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(n) or n == 0.0:
        raise FormatError("a VerseGrip orientation that is not a rotation")
    x, y, z, w = x / n, y / n, z / n, w / n
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    return quaternion_from_matrix(HAPLY_TO_DEVICE @ r @ HAPLY_TO_DEVICE.T)


def _object(text) -> dict:
    try:
        message = json.loads(text)
    except (TypeError, ValueError):
        raise FormatError(f"not JSON: {str(text)[:60]!r}") from None
    if not isinstance(message, dict):
        raise FormatError(f"a JSON {type(message).__name__}, not an object")
    return message


def _vector(entry: dict, key: str, names=("x", "y", "z")) -> list[float]:
    value = entry.get(key)
    try:
        out = [float(value[n]) for n in names]
    except (TypeError, KeyError, ValueError):
        raise FormatError(f"no {key} {{{', '.join(names)}}}") from None
    if not all(math.isfinite(v) for v in out):
        raise FormatError(f"a {key} that is not finite")
    return out


def inventory(text) -> tuple[int | None, list[dict]]:
    """(session_id, the Inverse3 entries) of the service's first message; FormatError when it
    is not a 3.x inventory."""
    message = _object(text)
    devices = message.get("inverse3")
    if not isinstance(devices, list):
        raise FormatError(f"no 'inverse3' list (keys: {', '.join(sorted(message)) or 'none'})")
    for entry in devices:
        if (
            not isinstance(entry, dict)
            or "device_id" not in entry
            or not isinstance(entry.get("state"), dict)
        ):
            raise FormatError("an 'inverse3' entry without device_id and state")
        _vector(entry["state"], "cursor_position")
    return message.get("session_id"), devices


def first_message(device_id) -> str:
    """The session's first message: its profile name, the workspace-centred preset, zero force."""
    return json.dumps(
        {
            "session": {"configure": {"profile": {"name": PROFILE_NAME}}},
            "inverse3": [
                {
                    "device_id": device_id,
                    "configure": {"preset": {"preset": PRESET}},
                    "commands": _force(np.zeros(3)),
                }
            ],
        }
    )


def force_message(device_id, device_force_n) -> str:
    return json.dumps({"inverse3": [{"device_id": device_id, "commands": _force(device_force_n)}]})


def _force(device_force_n) -> dict:
    fx, fy, fz = (float(v) for v in haply_force(device_force_n))
    return {"set_cursor_force": {"vector": {"x": fx, "y": fy, "z": fz}}}


def reading(text, device_id) -> Reading:
    """The state of `device_id` (and of the first wireless VerseGrip) in a state update."""
    message = _object(text)
    entry = next(
        (
            d
            for d in message.get("inverse3") or ()
            if isinstance(d, dict) and d.get("device_id") == device_id
        ),
        None,
    )
    if entry is None or not isinstance(entry.get("state"), dict):
        raise FormatError(f"a state update without Inverse3 {device_id}")
    state = entry["state"]
    status = entry.get("status") if isinstance(entry.get("status"), dict) else {}
    out = Reading(
        position_mm=position_mm(_vector(state, "cursor_position")),
        velocity_mm_s=position_mm(_vector(state, "cursor_velocity"))
        if "cursor_velocity" in state
        else np.zeros(3),
        calibrated=bool(status.get("calibrated", True)),
    )
    grips = message.get("wireless_verse_grip")
    if (
        isinstance(grips, list)
        and grips
        and isinstance(grips[0], dict)
        and isinstance(grips[0].get("state"), dict)
    ):
        grip = grips[0]["state"]
        pressed = grip.get("buttons") if isinstance(grip.get("buttons"), dict) else {}
        out.buttons = sum(1 << i for i, name in enumerate(GRIP_BUTTONS) if pressed.get(name))
        if "orientation" in grip:
            out.orientation = orientation(_vector(grip, "orientation", ("x", "y", "z", "w")))
    return out
