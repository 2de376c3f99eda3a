"""QuteMol edge cueing on the GPU against the numpy definition, and where lines and halos
fall on a scene of two spheres at different depths."""

from __future__ import annotations

import numpy as np
import pytest
from sasprobe.render.camera import fit_bounding_sphere
from sasprobe.render.gl.textures import read_texture
from sasprobe.render.lighting.edges import EdgeCueingProgram
from sasprobe.render.lighting.settings import EdgeCueing

from tests.references.lighting import edge_cueing, view_depths
from tests.support.lighting import camera, gbuffer_arrays, sphere_grid

pytestmark = pytest.mark.needs_gl(430)  # compute shaders, storage buffers


def test_edge_cueing_equals_the_numpy_definition(gl, crambin, crambin_grid):
    view, proj = camera(crambin)
    gbuffer, position, _, atom = gbuffer_arrays(crambin_grid, view, proj)
    edges = EdgeCueingProgram(gl)
    depth = view_depths(position, atom, view)
    for settings in (
        EdgeCueing(),
        EdgeCueing(contours=False, halos=True),
        EdgeCueing(halos=True, line_width=2.5),
    ):
        gpu = read_texture(edges.compute(gbuffer, view, proj, settings))
        cpu = edge_cueing(depth, atom, settings)
        assert np.abs(gpu - cpu).max() < 1e-3, settings
        assert (cpu < 0.5).sum() > 100  # lines / halos are really there
    edges.release()
    gbuffer.release()


def dilate(mask: np.ndarray, r: int) -> np.ndarray:
    """Pixels within a (2r+1)-square of a mask pixel."""
    rows = np.any([np.roll(mask, s, 0) for s in range(-r, r + 1)], axis=0)
    return np.any([np.roll(rows, s, 1) for s in range(-r, r + 1)], axis=0)


def test_lines_trace_depth_jumps_and_halos_fall_behind(gl):
    """A small sphere in front of a large one: lines on the large sphere around the small
    one's outline and along both outlines, none inside a sphere; halos only behind."""
    centers = np.array([[0.0, 0.0, 0.0], [2.0, 1.0, 9.0]])
    radii = np.array([6.0, 2.0])
    grid = sphere_grid(gl, centers, radii)
    view, proj = fit_bounding_sphere(centers, radii, 4 / 3, (0.0, 0.0, 1.0), fill=0.8)
    gbuffer, position, normal, atom = gbuffer_arrays(grid, view, proj, 128, 96)
    edges = EdgeCueingProgram(gl)
    lines = read_texture(edges.compute(gbuffer, view, proj, EdgeCueing()))
    halos = read_texture(edges.compute(gbuffer, view, proj, EdgeCueing(contours=False, halos=True)))
    front, back = atom == 1, atom == 0
    interior = lambda mask: mask & ~dilate(~mask, 3)  # noqa: E731
    # the small sphere's pixels are never behind anything: no line, no halo
    assert np.all(lines[front] == 1.0) and np.all(halos[front] == 1.0)
    # well inside either sphere, depth is smooth: no lines
    assert np.all(lines[interior(back) & ~dilate(front, 3)] == 1.0)
    # the large sphere is darkened right next to the small one (a line), and background
    # pixels next to either sphere (outlines)
    next_to_front = back & dilate(front, 1)
    assert lines[next_to_front].mean() < 0.2
    outline = (atom == -1) & dilate(atom != -1, 1)
    assert lines[outline].mean() < 0.2
    # halos: behind the small sphere, fading with distance from it
    assert halos[next_to_front].mean() < 0.7
    assert np.all(halos[back & ~dilate(front, 9)] == 1.0)
    edges.release()
    gbuffer.release()
    grid.release()
