"""G-buffer export (`--gbuffer FILE.npz`): a stable format for debugging and research.

Keys (row 0 is the top row of the image; H x W is the frame size):
    atom_id     int32   H x W      atom index; -1 background, -2 probe; backbone pixels
                                   carry the nearer trace (C-alpha / P) atom
    kind        uint8   H x W      0 background, 1 sphere surface, 2 cap (cut by a plane),
                                   3 backbone trace, 4 probe
    position    float32 H x W x 3  world position, Å (0 on background)
    normal      float32 H x W x 3  world unit normal (caps: the cutting plane's outward
                                   normal, -(a, b, c); 0 on background)
    view, proj  float64 4 x 4      OpenGL conventions, column vectors:
                                   clip = proj @ view @ [x, y, z, 1]
    viewport    int32   (2,)       (W, H)
    nav_cube    float64 (4,)       centre x, y, z and half edge, Å; absent when no cube is in effect
    nav_cube_axes float64 3 x 3    the cube's axes (columns; the device's x, y, z), with nav_cube
    probe       float64 (4,)       probe centre x, y, z and radius, Å; absent without a probe
    probe_goal  float64 (3,)       where the device tip maps (Å), when following a daemon
    device_tip_mm float64 (3,)     the device tip in the device frame (mm), when following a daemon
    clip_planes float64 N x 4      planes in effect (the user's, then the probe plane);
                                   a·x + b·y + c·z + d >= 0 is kept; unit normals
Passes add arrays of their own (Pass.exported_arrays); the lighting
(render/passes/lighting.py) adds, for what it computed in that frame:
    shadow_dir      float32 H x W  directional-light visibility 0..1 (1 lit; 0 shadowed or
                                   facing away)
    shadow_probe    float32 H x W  probe-light visibility 0..1 (1 beyond the light's range:
                                   not traced)
    ao              float32 H x W  ambient accessibility 0..1 (1 unoccluded)
    light_direction float64 (3,)   direction the directional light travels (as --light)
    probe_light     float64 (4,)   probe light position x, y, z and range, Å
Background and backbone-trace pixels are 1 in the lighting layers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sasprobe.common.errors import UserError


def gbuffer_arrays(renderer, frame=None) -> dict[str, np.ndarray]:
    """The G-buffer of a rendered frame (default: the last one) as numpy arrays."""
    frame = frame or renderer.last_frame
    t = renderer.targets
    ids = t.read(t.ids)
    arrays = {
        "atom_id": np.ascontiguousarray(ids[..., 0]),
        "kind": ids[..., 1].astype(np.uint8),
        "position": np.ascontiguousarray(t.read(t.position)[..., :3]),
        "normal": np.ascontiguousarray(t.read(t.normal)[..., :3]),
        "view": np.asarray(frame.view, dtype=np.float64),
        "proj": np.asarray(frame.proj, dtype=np.float64),
        "viewport": np.array(t.size, dtype=np.int32),
        "clip_planes": np.asarray(frame.planes, dtype=np.float64).reshape(-1, 4),
    }
    if frame.cube is not None:
        arrays["nav_cube"] = np.array([*frame.cube.center, frame.cube.half], dtype=np.float64)
        arrays["nav_cube_axes"] = np.asarray(frame.cube.axes, dtype=np.float64)
    probe = frame.scene.probe
    if probe is not None:
        arrays["probe"] = np.array([*probe.center, probe.radius], dtype=np.float64)
        if probe.goal is not None:
            arrays["probe_goal"] = np.asarray(probe.goal, dtype=np.float64)
        if probe.tip_mm is not None:
            arrays["device_tip_mm"] = np.asarray(probe.tip_mm, dtype=np.float64)
    for p in renderer.passes:
        if p.enabled(frame):
            arrays.update(p.exported_arrays(frame))
    return arrays


def save_gbuffer(path: str | Path, arrays: dict[str, np.ndarray], compress: bool = True) -> Path:
    """Write the arrays as .npz (`compress=False`: faster, for a G-buffer every frame)."""
    path = Path(path)
    try:
        with open(path, "wb") as fh:
            (np.savez_compressed if compress else np.savez)(fh, **arrays)
    except OSError as exc:
        raise UserError(f"{path}: cannot write the G-buffer ({exc.strerror or exc})") from None
    return path
