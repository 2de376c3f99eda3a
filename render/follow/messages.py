"""What a daemon's messages put into the renderer's SceneState: the scene message's probe
radius, planes, light, force ratings and marks, and the pose's probe, touched atom and
navigation cube. A live daemon (follow/daemon_source.py) and a recorded session
(render/playback.py) go through the same functions."""

from __future__ import annotations

import numpy as np
from sasprobe.render.scene_state import Mark, NavCube, Probe, normalise_plane


def apply_scene_message(scene, state: dict) -> bool:
    """A `scene` message's probe radius, clip planes, light direction, force ratings and marks
    into a SceneState (its grid then follows the daemon's probe radius); returns whether the
    daemon has the probe light on (the caller decides whether to follow)."""
    scene.probe_radius = float(state["probe_radius_A"])
    planes = [normalise_plane(p) for p in state["clip_planes"]]
    if len(planes) != len(scene.clip_planes) or any(
        not np.array_equal(a, b) for a, b in zip(planes, scene.clip_planes)
    ):
        scene.clip_planes = planes
    lights = state["lights"]
    direction = np.asarray(lights["directional"]["direction"], dtype=np.float64)
    scene.light_direction = direction / np.linalg.norm(direction)
    limits = state["device"].get("limits") or {}
    if "continuous_force_n" in limits and "max_force_n" in limits:
        scene.force_ratings_n = (float(limits["continuous_force_n"]), float(limits["max_force_n"]))
    marks = [
        Mark(int(m["id"]), m["label"], tuple(map(float, m["position_A"])))
        for m in state.get("marks", [])
    ]
    if marks != scene.marks:
        scene.marks = marks
    return bool(lights["probe"]["enabled"])


def apply_pose(scene, pose, cube_enabled: bool, axes: np.ndarray | None = None) -> None:
    """A pose's probe (with the device tip's goal and the force in the molecule frame), touched
    atom and navigation cube (turned with the view's `axes`) into a SceneState."""
    axes = np.eye(3) if axes is None else axes
    touched = pose.touched_atom if 0 <= pose.touched_atom < scene.structure.n_atoms else -1
    scene.probe = Probe(
        center=np.array(pose.proxy_A, dtype=np.float64),
        radius=scene.probe_radius,
        touched_atom=touched,
        goal=np.array(pose.goal_A, dtype=np.float64),
        force_n=axes @ np.asarray(pose.force_N, dtype=np.float64),
        tip_mm=np.array(pose.tip_mm, dtype=np.float64),
    )
    if cube_enabled and pose.cube_half_A > 0 and np.all(np.isfinite(pose.cube_center_A)):
        cube = NavCube(
            center=np.array(pose.cube_center_A, dtype=np.float64),
            half=float(pose.cube_half_A),
            axes=axes,
        )
        if scene.nav_cube is None or scene.nav_cube.key() != cube.key():
            scene.nav_cube = cube
    else:
        scene.nav_cube = None
