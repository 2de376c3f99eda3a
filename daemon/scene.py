"""The scene message as the daemon fills it (the keys are protocol/README.md's)."""

from __future__ import annotations

from sasprobe import __version__
from sasprobe.devices.base import DeviceInfo
from sasprobe.protocol.scene import SCENE_VERSION


def scene_message(revision: int, structure, settings: dict, nav_cube_enabled: bool, clip_planes: list,
                  lights: dict, device: DeviceInfo, rate_hz: float | None, marks) -> dict:
    return {
        "version": SCENE_VERSION,
        "revision": revision,
        "daemon_version": __version__,
        "structure": {"name": structure.name, "sha256": structure.sha256, "n_atoms": structure.n_atoms},
        "probe_radius_A": settings["probe_radius_A"],
        "nav_cube": {"enabled": nav_cube_enabled},
        "clip_planes": clip_planes,
        "lights": lights,
        "device": device.as_dict(),
        "haptics": {"method": settings["method"], "stiffness_n_per_mm": settings["stiffness_n_per_mm"],
                    "damping_n_s_per_m": settings["damping_n_s_per_m"]},
        "rate_hz": rate_hz,
        "marks": marks.scene(structure.sha256),
    }
