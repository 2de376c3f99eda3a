"""Shared set-up of the lighting tests: small scenes and their G-buffers (the GL context,
1CRN and its GPU grid are fixtures in conftest.py; the lighting needs OpenGL 4.3, which
each lighting test module asks for with `pytest.mark.needs_gl(430)`)."""

from __future__ import annotations

import numpy as np
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid
from sasprobe.render.camera import fit_bounding_sphere
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.gbuffer import RaycastGBuffer
from sasprobe.render.lighting.uploaded_grid import UploadedGrid

WIDTH, HEIGHT = 128, 96
VIEW_DIRECTION = (0.3, 0.4, 1.0)


def cullings(structure) -> dict[str, Culling]:
    """No culling; an oblique clip plane near the middle; a navigation cube off-centre."""
    centre = structure.positions.mean(axis=0)
    normal = -np.array([1.0, 0.2, 0.5]) / np.linalg.norm([1.0, 0.2, 0.5])  # caps face the camera
    return {
        "none": Culling(),
        "plane": Culling(clip_planes=[[*normal, -float(normal @ centre) + 2.0]]),
        "cube": Culling(nav_cube=(centre + [2.0, -1.0, 0.0], 8.0)),
    }


def camera(structure, width=WIDTH, height=HEIGHT, fill=1.25):
    return fit_bounding_sphere(
        structure.positions, structure.vdw_radii, width / height, VIEW_DIRECTION, fill=fill
    )


def gbuffer_arrays(gpu_grid, view, proj, width=WIDTH, height=HEIGHT):
    """(GBuffer, position, normal, atom id) traced through the grid on the GPU."""
    caster = RaycastGBuffer(gpu_grid)
    gbuffer = caster.render(view, proj, width, height)
    caster.release()
    return (gbuffer, *gbuffer.download())


def probe_on_surface(
    structure, direction=VIEW_DIRECTION, probe_radius=DEFAULT_PROBE_RADIUS, lift=0.2
):
    """A probe centre on the solvent accessible surface: leaving the molecule's centre along
    `direction`, the first point outside every expanded sphere (+ `lift` Å)."""
    direction = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    centre = structure.positions.mean(axis=0)
    t = np.arange(0.0, 80.0, 0.05)
    points = centre + t[:, None] * direction
    gaps = (
        np.linalg.norm(points[:, None, :] - structure.positions[None], axis=-1)
        - structure.vdw_radii
        - probe_radius
    )
    inside = np.flatnonzero(np.min(gaps, axis=1) < 0)
    return centre + (t[inside[-1]] + 0.05 + lift) * direction


def sphere_grid(gl, centers, radii, pad=DEFAULT_PROBE_RADIUS) -> UploadedGrid:
    """A UploadedGrid over hand-placed spheres (expanded by `pad`, as the daemon's grid is)."""
    centers = np.asarray(centers, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    return UploadedGrid(gl, UniformGrid(centers, radii + pad), radii)


def away_from_boundaries(classes: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Valid pixels with no valid 8-neighbour of another class: the one-pixel margin around
    every lit/shadowed boundary is left out (background neighbours do not count)."""
    h, w = classes.shape
    padded = np.pad(classes, 1, mode="edge")
    padded_valid = np.pad(valid, 1, mode="constant", constant_values=False)
    keep = valid.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            other = padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
            other_valid = padded_valid[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
            keep &= ~other_valid | (other == classes)
    return keep
