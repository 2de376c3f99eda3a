"""The grid on the GPU: buffers, culled flags, the shaders' 3D-DDA against the CPU walk
(UniformGrid.ray_cells), and closest-hit traversal against a brute-force ray caster."""

from __future__ import annotations

import numpy as np
import pytest
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid
from sasprobe.render.gl.targets import KIND_CAP
from sasprobe.render.gl.textures import TABLE_ROW
from sasprobe.render.lighting.culling import LIGHT_CUT_MARGIN, Culling
from sasprobe.render.lighting.uploaded_grid import (
    CENTRE_CLIPPED,
    CULLED,
    UploadedGrid,
    walk_rays_on_gpu,
)

from tests.references.lighting import Occluders, raycast_gbuffer
from tests.support.lighting import camera, cullings, gbuffer_arrays

pytestmark = pytest.mark.needs_gl(430)  # compute shaders, storage buffers


def random_rays(grid: UniformGrid, n: int, seed: int, margin: float = 0.3):
    """Rays from inside and around the grid (a `margin` of its span on each side), a tenth
    of them parallel to an axis."""
    rng = np.random.default_rng(seed)
    lo, hi = grid.origin, grid.upper
    span = hi - lo
    origins = lo - margin * span + rng.random((n, 3)) * (1 + 2 * margin) * span
    directions = rng.normal(size=(n, 3))
    axis_parallel = rng.random(n) < 0.1
    directions[axis_parallel] = np.eye(3)[rng.integers(0, 3, axis_parallel.sum())] * rng.choice(
        [-1, 1], (axis_parallel.sum(), 1)
    )
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    return origins, directions


def compare_walks(grid: UniformGrid, gpu, origins, directions, t_min, t_max, keep=None):
    """Rays whose GPU cell sequence differs from the CPU one; a difference is only excused
    where the CPU walk crosses two cell faces within float32 rounding of each other."""
    unexplained, near_ties, cells_total = [], 0, 0
    for i in range(origins.shape[0]):
        cells, t_enter, t_exit = grid.ray_cells(origins[i], directions[i], t_min, t_max)
        if keep is not None:
            inside = keep(cells)
            cells, t_enter, t_exit = cells[inside], t_enter[inside], t_exit[inside]
        got_cells, got_t = gpu.ray(i)
        cells_total += len(cells)
        if len(cells) == len(got_cells) and np.array_equal(cells, got_cells):
            if len(cells):
                scale = 1e-4 * (1.0 + np.abs(t_exit).max())
                assert np.allclose(got_t[:, 0], t_enter, atol=scale) and np.allclose(
                    got_t[:, 1], t_exit, atol=scale
                ), i
            continue
        crossings = np.diff(t_exit[:-1]) if len(t_exit) > 2 else np.array([])
        if crossings.size and np.min(np.abs(crossings)) < 1e-5 * (1.0 + np.abs(t_exit).max()):
            near_ties += 1
        else:
            unexplained.append(i)
    return unexplained, near_ties, cells_total


@pytest.mark.parametrize("cell_size", [None, 2.7])
def test_gpu_dda_visits_the_same_cells_as_the_cpu_walk(gl, crambin, cell_size):
    grid = UniformGrid(crambin.positions, crambin.expanded_radii(DEFAULT_PROBE_RADIUS), cell_size)
    gpu_grid = UploadedGrid(gl, grid, crambin.vdw_radii)
    origins, directions = random_rays(grid, 1500, seed=11)
    walks = walk_rays_on_gpu(gpu_grid, origins, directions, max_visits=int(grid.dims.sum()) + 2)
    unexplained, near_ties, cells_total = compare_walks(
        grid, walks, origins, directions, 0.0, np.inf
    )
    assert cells_total > 2000  # the rays really cross the grid
    assert unexplained == []
    assert near_ties <= 3
    gpu_grid.release()


def test_gpu_dda_respects_segment_and_cell_range(gl, crambin, crambin_grid):
    grid = crambin_grid.grid
    origins, directions = random_rays(grid, 1000, seed=5, margin=0.0)
    # a segment of each ray
    walks = walk_rays_on_gpu(crambin_grid, origins, directions, t_min=3.0, t_max=17.0)
    unexplained, near_ties, cells_total = compare_walks(grid, walks, origins, directions, 3.0, 17.0)
    assert cells_total > 500 and unexplained == [] and near_ties <= 2
    # a sub-range of cells (the navigation cube's): the CPU walk's cells inside that range
    lo, hi = np.array([1, 1, 1]), grid.dims - 2
    walks = walk_rays_on_gpu(crambin_grid, origins, directions, walk_range=(lo, hi))
    inside = lambda cells: np.all((cells >= lo) & (cells <= hi), axis=1)  # noqa: E731
    unexplained, near_ties, cells_total = compare_walks(
        grid, walks, origins, directions, 0.0, np.inf, keep=inside
    )
    assert cells_total > 500 and unexplained == [] and near_ties <= 2


def test_buffers_hold_the_cpu_grid(gl, crambin, crambin_grid):
    grid = crambin_grid.grid
    assert np.array_equal(np.frombuffer(crambin_grid.cell_start.read(), np.uint32), grid.cell_start)
    assert np.array_equal(np.frombuffer(crambin_grid.cell_atoms.read(), np.uint32), grid.cell_atoms)
    spheres = np.frombuffer(crambin_grid.spheres.read(), np.float32).reshape(-1, 4)[
        : crambin.n_atoms
    ]
    assert np.allclose(spheres[:, :3], crambin.positions, atol=1e-4)
    assert np.array_equal(spheres[:, 3], crambin.vdw_radii.astype(np.float32))
    # 327 atoms fill one row of each table; a table takes 3, its height no power of two
    # (steady_side)
    assert crambin_grid.nbytes == grid.nbytes + 3 * TABLE_ROW * 20
    assert crambin_grid.max_shell == pytest.approx(DEFAULT_PROBE_RADIUS)


def test_culled_flags_follow_planes_and_cube(gl, crambin, crambin_grid):
    centers, radii = crambin.positions, crambin.vdw_radii
    for name, culling in cullings(crambin).items():
        crambin_grid.set_culling(culling)
        flags = np.frombuffer(crambin_grid.culled.read(), np.uint32)[: crambin.n_atoms]
        # brute force: nothing kept = wholly behind a plane, or not touching the cube
        expect = np.zeros(crambin.n_atoms, dtype=bool)
        centre_out = np.zeros(crambin.n_atoms, dtype=bool)
        for plane in culling.clip_planes:
            signed = centers @ plane[:3] + plane[3]
            expect |= signed < -radii
            centre_out |= signed < 0
        if culling.nav_cube is not None:
            c, h = culling.nav_cube
            gap = np.maximum(np.abs(centers - c) - h, 0.0)
            expect |= np.sum(gap**2, axis=1) > radii**2
            centre_out |= np.any(np.abs(centers - c) > h, axis=1)
        assert np.array_equal((flags & CULLED) != 0, expect), name
        assert np.array_equal((flags & CENTRE_CLIPPED) != 0, centre_out), name
        assert name == "none" or 0 < expect.sum() < crambin.n_atoms
    crambin_grid.set_culling(Culling())


def test_the_cuts_a_point_light_lies_beyond():
    """A shadow ray from a kept point to the light can only be shortened by the planes and
    cube faces the light is not inside (a half-space holds every segment between two of
    its points); those within LIGHT_CUT_MARGIN of the light count as crossed."""
    plane = [0.0, 0.0, 1.0, -1.0]  # kept where z >= 1
    culling = Culling(clip_planes=[plane], nav_cube=(np.zeros(3), 5.0))
    inside = culling.cuts_before([0.0, 0.0, 2.0])
    assert inside.clip_planes.shape == (0, 4) and inside.nav_cube is None and not inside.clipping
    beyond = culling.cuts_before([0.0, 0.0, 0.0])
    assert np.allclose(beyond.clip_planes, [plane]) and beyond.nav_cube is None
    outside = culling.cuts_before(
        [7.0, 0.0, 1.0 + LIGHT_CUT_MARGIN / 2]
    )  # beyond the cube's +x face, on the plane
    assert np.allclose(outside.clip_planes, [plane, [-1.0, 0.0, 0.0, 5.0]])
    x = np.array([[7.0, 0.0, 3.0], [4.0, 0.0, 3.0]])  # the +x face cuts where the cube would
    kept = x @ outside.clip_planes[:, :3].T + outside.clip_planes[:, 3] >= 0
    assert kept.all(axis=1).tolist() == [False, True]
    assert culling.cuts_before([0.0, 0.0, 0.0]) is beyond  # found once for the same cuts
    crowded = Culling(
        clip_planes=np.tile([1.0, 0.0, 0.0, -1.0], (24, 1)), nav_cube=(np.zeros(3), 0.5)
    )
    assert (
        crowded.cuts_before([0.499, 0.0, 0.0]) is crowded
    )  # 25: too many for the shaders, every cut as drawn


def test_too_many_clip_planes_is_refused():
    with pytest.raises(ValueError, match="at most"):
        Culling(clip_planes=np.tile([1.0, 0.0, 0.0, 0.0], (25, 1)))


@pytest.mark.parametrize("which", ["none", "plane", "cube"])
def test_closest_hit_traversal_matches_brute_force_ray_casting(gl, crambin, crambin_grid, which):
    crambin_grid.set_culling(cullings(crambin)[which])
    crambin_grid.set_probe(crambin.positions.mean(axis=0) + [0.0, 0.0, 14.0], DEFAULT_PROBE_RADIUS)
    view, proj = camera(crambin)
    gbuffer, position, normal, atom = gbuffer_arrays(crambin_grid, view, proj)
    kinds = gbuffer.kinds()
    gbuffer.release()
    ref_position, ref_normal, ref_atom = raycast_gbuffer(
        view, proj, atom.shape[1], atom.shape[0], Occluders.of(crambin_grid)
    )
    crambin_grid.set_culling(Culling())
    crambin_grid.set_probe(None)
    assert (atom >= 0).mean() > 0.15 and (atom == -2).sum() > 5  # molecule and probe in view
    assert (atom == ref_atom).mean() >= 0.995
    same = (atom == ref_atom) & (atom != -1)
    assert np.abs(position[same] - ref_position[same]).max() < 1e-3
    assert np.abs(normal[same] - ref_normal[same]).max() < 1e-3
    if which == "plane":  # caps: on the plane, with its outward normal
        plane = cullings(crambin)["plane"].clip_planes[0]
        caps = same & np.all(np.isclose(normal, -plane[:3], atol=1e-4), axis=-1)
        assert caps.sum() > 50
        assert np.array_equal(kinds[same] == KIND_CAP, caps[same])
        assert np.abs(position[caps] @ plane[:3] + plane[3]).max() < 1e-3
