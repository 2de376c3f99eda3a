"""The scene message as the daemon fills it (the keys are protocol/README.md's)."""

from __future__ import annotations

from sasprobe.devices.base import DeviceInfo
from sasprobe.protocol.scene import SCENE_VERSION

from sasprobe import __version__


def rotation_rows(rotation) -> list[list[float]]:
    """A view rotation's 9 floats (row-major) as the 3 rows the wire carries."""
    r = [float(v) for v in rotation]
    return [r[0:3], r[3:6], r[6:9]]


def scene_message(
    revision: int,
    structure,
    settings: dict,
    nav_cube_enabled: bool,
    clip_planes: list,
    lights: dict,
    device: DeviceInfo,
    rate_hz: float | None,
    view_rotation,
    marks,
    color_scheme: str | None = None,
    pose_every: int = 1,
) -> dict:
    return {
        "version": SCENE_VERSION,
        "revision": revision,
        "daemon_version": __version__,
        "structure": {
            "name": structure.name,
            "sha256": structure.sha256,
            "n_atoms": structure.n_atoms,
        },
        "probe_radius_A": settings["probe_radius_A"],
        "nav_cube": {"enabled": nav_cube_enabled},
        "clip_planes": clip_planes,
        "lights": lights,
        "device": device.as_dict(),
        "haptics": {
            "method": settings["method"],
            "stiffness_n_per_mm": settings["stiffness_n_per_mm"],
            "damping_n_s_per_m": settings["damping_n_s_per_m"],
        },
        "rate_hz": rate_hz,
        "pose_every": pose_every,
        "view": {"rotation": rotation_rows(view_rotation)},
        "color_scheme": color_scheme,
        "marks": marks.scene(structure.sha256),
    }
