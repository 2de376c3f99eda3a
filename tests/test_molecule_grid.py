"""Uniform grid against brute force: sphere queries, box->cells, 3D-DDA, k nearest."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sasprobe.molecule import UniformGrid, load_default, load_structure

CRAMBIN = load_default()
CENTERS = CRAMBIN.positions
RADII = CRAMBIN.expanded_radii(1.4)
CELL_SIZES = [None, 2.0, 3.7, 9.5, 40.0]  # default, small, odd, large, one cell
GRIDS = {c: UniformGrid(CENTERS, RADII, c) for c in CELL_SIZES}
LO = CENTERS.min(axis=0) - 12
HI = CENTERS.max(axis=0) + 12  # queries reach outside the grid

coord = st.floats(0.0, 1.0)
point = st.tuples(coord, coord, coord).map(lambda t: LO + np.array(t) * (HI - LO))
cell_size = st.sampled_from(CELL_SIZES)


def brute_cells_of_box(grid: UniformGrid, lo, hi) -> set[int]:
    """Every cell whose half-open box [a, a+h) overlaps the closed box [lo, hi]."""
    found = set()
    h = grid.cell_size
    for iz in range(grid.dims[2]):
        for iy in range(grid.dims[1]):
            for ix in range(grid.dims[0]):
                a = grid.origin + np.array([ix, iy, iz]) * h
                if np.all(lo < a + h) and np.all(hi >= a):
                    found.add(ix + grid.dims[0] * (iy + grid.dims[1] * iz))
    return found


def test_default_cell_size_puts_each_sphere_in_at_most_8_cells():
    grid = GRIDS[None]
    assert grid.cell_size == pytest.approx(2 * RADII.max())
    per_sphere = np.bincount(grid.cell_atoms, minlength=len(CENTERS))
    assert per_sphere.max() <= 8 and per_sphere.min() >= 1


@pytest.mark.parametrize("size", CELL_SIZES)
def test_each_sphere_is_stored_in_exactly_the_cells_its_box_overlaps(size):
    grid = GRIDS[size]
    stored = {c: set(grid.atoms_in_cell(c).tolist()) for c in range(grid.n_cells)}
    for i in range(0, len(CENTERS), 7):
        expected = brute_cells_of_box(grid, CENTERS[i] - RADII[i], CENTERS[i] + RADII[i])
        actual = {c for c, members in stored.items() if i in members}
        assert actual == expected, i
    for c in range(grid.n_cells):  # sorted, unique within a cell
        members = grid.atoms_in_cell(c)
        assert np.all(np.diff(members.astype(np.int64)) > 0)


@settings(max_examples=150, deadline=None)
@given(p=point, d=st.floats(0.0, 8.0), size=cell_size)
def test_spheres_within_equals_brute_force(p, d, size):
    grid = GRIDS[size]
    dist = np.linalg.norm(CENTERS - p, axis=1) - RADII
    expected = np.flatnonzero(dist <= d)
    np.testing.assert_array_equal(grid.spheres_within(p, d), expected)


@settings(max_examples=60, deadline=None)
@given(a=point, b=point, size=cell_size)
def test_box_to_cells_equals_brute_force(a, b, size):
    grid = GRIDS[size]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    rng = grid.cell_range(lo, hi)
    got = set() if rng is None else set(grid.cells_in_range(*rng).tolist())
    assert got == brute_cells_of_box(grid, lo, hi)
    # and the spheres overlapping the box, by an exact closest-point test
    nearest = np.clip(CENTERS, lo, hi)
    expected = np.flatnonzero(np.linalg.norm(CENTERS - nearest, axis=1) <= RADII)
    np.testing.assert_array_equal(grid.spheres_in_box(lo, hi), expected)


def dense_cells(grid: UniformGrid, o, d, t0, t1, n=20000):
    """Cells a dense sampling of the segment visits, consecutive duplicates removed."""
    t = np.linspace(t0, t1, n)
    pts = o + t[:, None] * d
    inside = np.all((pts >= grid.origin) & (pts < grid.upper), axis=1)
    idx = np.floor((pts[inside] - grid.origin) / grid.cell_size).astype(int)
    keep = np.ones(len(idx), bool)
    keep[1:] = np.any(idx[1:] != idx[:-1], axis=1)
    return idx[keep], (t1 - t0) / (n - 1)


@settings(max_examples=80, deadline=None)
@given(a=point, b=point, size=cell_size, extend=st.booleans())
def test_dda_visits_the_cells_of_dense_sampling_in_order(a, b, size, extend):
    grid = GRIDS[size]
    d = b - a
    if np.linalg.norm(d) < 1e-6:
        return
    t_max = 3.0 if extend else 1.0
    cells, t_in, t_out = grid.ray_cells(a, d, 0.0, t_max)
    # entry/exit t are contiguous and monotone, and each interval lies in its cell
    if len(cells):
        assert np.all(t_out >= t_in)
        np.testing.assert_allclose(t_in[1:], t_out[:-1])
        assert np.all(np.diff(t_in) >= 0)
        mids = a + ((t_in + t_out) / 2)[:, None] * d
        np.testing.assert_array_equal(grid.cell_index(mids), cells)
        assert np.all(np.abs(np.diff(cells, axis=0)).sum(axis=1) == 1)  # face neighbours
    sampled, dt = dense_cells(grid, a, d, 0.0, t_max)
    # every cell the samples see is visited, in the same order; cells the samples skip
    # can only be corner clips shorter than the sample spacing
    long_enough = (t_out - t_in) > 2 * dt
    visited = [tuple(c) for c in cells]
    seen = [tuple(c) for c in sampled]
    it = iter(visited)
    assert all(any(c == v for v in it) for c in seen), (
        "sampled cells not a subsequence of the DDA walk"
    )
    assert {tuple(c) for c in cells[long_enough]} <= set(seen)


def test_dda_axis_aligned_and_outside_rays():
    grid = GRIDS[None]
    o = grid.origin + np.array([-5.0, 0.5, 0.5]) * [1, grid.cell_size, grid.cell_size]
    cells, t_in, t_out = grid.ray_cells(o, np.array([1.0, 0, 0]))
    assert len(cells) == grid.dims[0]
    assert np.all(cells[:, 1:] == 0) and np.array_equal(cells[:, 0], np.arange(grid.dims[0]))
    assert t_in[0] == pytest.approx(5.0)
    # a ray that misses the grid, and one pointing away, visit nothing
    assert len(grid.ray_cells(grid.upper + 1, np.array([1.0, 0, 0]))[0]) == 0
    assert len(grid.ray_cells(o, np.array([-1.0, 0, 0]))[0]) == 0


@pytest.mark.parametrize("k", [1, 8, 16, 32])
@pytest.mark.parametrize("size", [None, 2.0, 40.0])
def test_nearest_neighbours_equal_a_brute_force_sort(k, size):
    grid = GRIDS[size]
    idx, dist = grid.nearest_neighbors(k)
    full = np.linalg.norm(CENTERS[:, None] - CENTERS[None], axis=2)
    np.fill_diagonal(full, np.inf)
    expected = np.argsort(full, axis=1, kind="stable")[:, :k]
    np.testing.assert_array_equal(idx, expected)
    np.testing.assert_allclose(dist, np.take_along_axis(full, expected, axis=1))


@pytest.mark.parametrize("size", [None, 2.0, 40.0])
def test_nearest_neighbours_of_some_spheres_equal_a_brute_force_sort(size):
    """Asked for a few spheres (in any order, repeated), the rows are those spheres' own."""
    grid = GRIDS[size]
    of = np.array([200, 3, 77, 3, 326, 0])
    idx, dist = grid.nearest_neighbors(16, of=of)
    full = np.linalg.norm(CENTERS[of, None] - CENTERS[None], axis=2)
    full[np.arange(of.size), of] = np.inf
    expected = np.argsort(full, axis=1, kind="stable")[:, :16]
    np.testing.assert_array_equal(idx, expected)
    np.testing.assert_allclose(dist, np.take_along_axis(full, expected, axis=1))


@settings(max_examples=60, deadline=None)
@given(point, cell_size, st.sampled_from([1, 5, 32]))
def test_nearest_to_a_point_equals_a_brute_force_sort(p, size, k):
    d = np.linalg.norm(CENTERS - p, axis=1)
    expected = np.lexsort((np.arange(d.size), d))[:k]
    np.testing.assert_array_equal(GRIDS[size].nearest_to_point(p, k), expected)


def test_nearest_to_a_point_pads_when_too_few_spheres():
    grid = UniformGrid(np.array([[0.0, 0, 0], [1.0, 0, 0]]), np.full(2, 1.0))
    np.testing.assert_array_equal(grid.nearest_to_point((9.0, 0.0, 0.0), 4), [1, 0, -1, -1])


def test_nearest_neighbours_pad_when_too_few_spheres():
    grid = UniformGrid(np.array([[0.0, 0, 0], [1.0, 0, 0], [5.0, 0, 0]]), np.full(3, 1.0))
    idx, dist = grid.nearest_neighbors(4)
    np.testing.assert_array_equal(idx[0], [1, 2, -1, -1])
    assert np.isinf(dist[0, 2:]).all()


def test_stats_match_the_arrays(reference_by_id):
    s = load_structure(reference_by_id["1tii"].path)
    grid = UniformGrid(s.positions, s.expanded_radii(1.4))
    stats = grid.stats()
    counts = np.array([len(grid.atoms_in_cell(c)) for c in range(grid.n_cells)])
    assert stats.n_cells == np.prod(stats.dims) == len(counts)
    assert stats.n_nonempty == np.count_nonzero(counts)
    assert stats.max_per_cell == counts.max()
    assert stats.mean_per_nonempty == pytest.approx(counts[counts > 0].mean())
    assert stats.bytes == grid.cell_start.nbytes + grid.cell_atoms.nbytes
    assert grid.cell_start.dtype == np.uint32 and grid.cell_atoms.dtype == np.uint32


def test_bad_grid_input_is_refused():
    with pytest.raises(ValueError):
        UniformGrid(np.zeros((0, 3)), np.zeros(0))
    with pytest.raises(ValueError):
        UniformGrid(CENTERS, RADII, cell_size=0.0)
    with pytest.raises(ValueError):
        UniformGrid(CENTERS, RADII, cell_size=1e-3)  # billions of cells


@pytest.mark.parametrize("size", [None, 2.0, 40.0])
def test_overlapping_pairs_equal_brute_force(size):
    i, j = GRIDS[size].overlapping_pairs()
    dist = np.linalg.norm(CENTERS[:, None] - CENTERS[None], axis=2)
    expected_i, expected_j = np.nonzero(
        (dist < RADII[:, None] + RADII[None]) & ~np.eye(len(CENTERS), dtype=bool)
    )
    np.testing.assert_array_equal(i, expected_i)
    np.testing.assert_array_equal(j, expected_j)
