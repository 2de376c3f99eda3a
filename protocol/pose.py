"""The `pose` message: one fixed-size little-endian record per daemon tick.

The byte layout and the flag bits are protocol/schemas/pose.json's (protocol/README.md
shows them): the struct format and the flag values come from there, and the tests check
this codec against a decoder built from the README's table.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np
from sasprobe.protocol.schemas import pose_flag, pose_layout, pose_struct_format

POSE_TOPIC = b"pose"
POSE_VERSION = pose_layout()["version"]

# version, flags, buttons, seq, device_t_ns, publish_t_ns, proxy[3], goal[3], force[3],
# tip[3], orientation[4], touched_atom, reserved, cube_center[3], cube_half (encode_pose's order)
_LAYOUT = struct.Struct(pose_struct_format())
POSE_SIZE = _LAYOUT.size  # 200 bytes
if POSE_SIZE != pose_layout()["size"]:
    raise ImportError(
        f"protocol/schemas/pose.json: its fields make {POSE_SIZE} bytes, not "
        f"{pose_layout()['size']}"
    )

FLAG_CONTACT = pose_flag("contact")  # the proxy touches the SAS
FLAG_CLAMPED = pose_flag("clamped")  # the force was clamped to the device limit
# the watchdog zeroed the force (device fault, late tick, bad values)
FLAG_FAULT = pose_flag("fault")
# the navigation cube is drifting (tip in the workspace margin)
FLAG_DRIFTING = pose_flag("drifting")
FLAG_RAMPING = pose_flag("ramping")  # forces are still ramping up after start or reconnect
# the clutch is held: the probe stays, the cube follows the hand, no force
FLAG_CLUTCHED = pose_flag("clutched")


class PoseDecodeError(ValueError):
    """A payload that is not a pose this reader understands."""


def _vec(n: int) -> np.ndarray:
    return np.zeros(n, dtype=np.float64)


@dataclass
class Pose:
    seq: int = 0
    device_t_ns: int = 0
    publish_t_ns: int = 0
    proxy_A: np.ndarray = field(default_factory=lambda: _vec(3))  # probe centre, molecule frame
    goal_A: np.ndarray = field(default_factory=lambda: _vec(3))  # device tip mapped to the molecule
    # force sent to the device, device frame
    force_N: np.ndarray = field(default_factory=lambda: _vec(3))
    tip_mm: np.ndarray = field(default_factory=lambda: _vec(3))  # device tip, device frame
    # w, x, y, z
    orientation: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    buttons: int = 0
    touched_atom: int = -1
    flags: int = 0
    cube_center_A: np.ndarray = field(default_factory=lambda: _vec(3))
    cube_half_A: float = 0.0
    version: int = POSE_VERSION

    def has(self, flag: int) -> bool:
        return bool(self.flags & flag)


def encode_pose(pose: Pose) -> bytes:
    # One concatenate + tolist instead of per-field conversions: this runs every tick.
    vectors = np.concatenate(
        (
            pose.proxy_A,
            pose.goal_A,
            pose.force_N,
            pose.tip_mm,
            pose.orientation,
            pose.cube_center_A,
        ),
        dtype=np.float64,
    )
    if vectors.shape != (19,):
        raise ValueError("pose vectors must be 3 values each (orientation: 4)")
    v = vectors.tolist()
    return _LAYOUT.pack(
        POSE_VERSION,
        pose.flags & 0xFFFF,
        pose.buttons & 0xFFFFFFFF,
        pose.seq,
        pose.device_t_ns,
        pose.publish_t_ns,
        *v[:16],
        pose.touched_atom,
        0,
        *v[16:],
        float(pose.cube_half_A),
    )


def decode_pose(payload: bytes) -> Pose:
    """Decode a pose; later versions may append fields, which this reader skips."""
    if len(payload) < 2:
        raise PoseDecodeError(f"pose payload of {len(payload)} bytes is too short")
    (version,) = struct.unpack_from("<H", payload, 0)
    if version < POSE_VERSION:
        raise PoseDecodeError(f"pose version {version} is older than this reader's {POSE_VERSION}")
    if len(payload) < POSE_SIZE:
        raise PoseDecodeError(
            f"pose payload of {len(payload)} bytes, expected at least {POSE_SIZE}"
        )
    v = _LAYOUT.unpack_from(payload, 0)
    return Pose(
        version=v[0],
        flags=v[1],
        buttons=v[2],
        seq=v[3],
        device_t_ns=v[4],
        publish_t_ns=v[5],
        proxy_A=np.array(v[6:9]),
        goal_A=np.array(v[9:12]),
        force_N=np.array(v[12:15]),
        tip_mm=np.array(v[15:18]),
        orientation=np.array(v[18:22]),
        touched_atom=v[22],
        cube_center_A=np.array(v[24:27]),
        cube_half_A=v[27],
    )
