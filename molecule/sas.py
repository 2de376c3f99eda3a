"""Solvent accessible surface area by Shrake & Rupley (1973), on the spheres that are felt.

Each atom's expanded sphere (vdW + probe radius) carries the same set of unit test
points (a golden-section spiral). Neighbour j buries point u of atom i exactly when u
lies in the spherical cap that sphere j cuts from sphere i:

    |R_i u + c_i - c_j| < R_j   <=>   u . n_ij > (R_i^2 + d^2 - R_j^2) / (2 R_i d),

with d = |c_j - c_i| and n_ij the unit vector from c_i to c_j. So the whole test is one
matrix product (pairs x 3) @ (3 x points) and a comparison, done in chunks of pairs;
overlapping pairs come from the uniform grid. No per-atom Python loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sasprobe.molecule.grid import UniformGrid

DEFAULT_POINTS = 512
REFINE_POINTS = 2048
REFINE_BELOW = 1.5  # Å^2: atoms with a small non-zero coarse area are re-sampled finely
# An atom is "accessible" when at least this much of its SAS is exposed. Below it the
# answer depends on resolution even between exact methods: on 1TII FreeSASA's own
# Lee-Richards (200 slices) and Shrake-Rupley (5000 points) agree on only 97.9 % of
# atoms for "area > 0", but on 99.9 % for "area >= 0.5 Å^2".
ACCESSIBLE_MIN_AREA = 0.5
# pairs x points per matrix product: about a million keeps the product, the comparison
# and the packed bits in cache (`sasprobe bench sas` times it)
_CHUNK_ELEMENTS = 1 << 20


@dataclass
class SasResult:
    areas: np.ndarray  # (N,) Å^2 per atom
    expanded_radii: np.ndarray  # (N,) Å, the spheres used
    n_points: int
    refine_points: int
    n_refined: int

    @property
    def accessible(self) -> np.ndarray:
        return self.areas >= ACCESSIBLE_MIN_AREA

    @property
    def total(self) -> float:
        return float(self.areas.sum())


def sphere_points(n: int) -> np.ndarray:
    """n nearly uniform unit vectors (golden-section spiral), (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5.0**0.5) * k
    return np.column_stack((r * np.cos(phi), r * np.sin(phi), z))


def shrake_rupley(
    grid: UniformGrid, n_points: int = DEFAULT_POINTS, refine_points: int = REFINE_POINTS
) -> SasResult:
    """Per-atom SAS area of the spheres held by `grid` (centres, expanded radii).

    All atoms are sampled with `n_points`; atoms whose area comes out small but
    non-zero are sampled again with `refine_points`, so areas near the accessibility
    threshold are precise without paying the fine resolution everywhere.
    """
    i, j = grid.overlapping_pairs()
    areas, refined = _areas(
        grid, i, j, np.ones(grid.centers.shape[0], dtype=bool), n_points, refine_points
    )
    return SasResult(
        areas=areas,
        expanded_radii=grid.radii.copy(),
        n_points=n_points,
        refine_points=refine_points,
        n_refined=int(refined.sum()),
    )


def atom_areas(
    grid: UniformGrid, atoms, n_points: int = DEFAULT_POINTS, refine_points: int = REFINE_POINTS
) -> np.ndarray:
    """SAS areas (Å^2) of some atoms only, sampled and refined as `shrake_rupley` does;
    their overlapping neighbours come from the grid's sphere query (a clicked atom's area
    without computing the whole structure's)."""
    atoms = np.unique(np.asarray(atoms, dtype=np.int64).reshape(-1))
    owners, others = [], []
    for a in atoms:  # sorted, so the pairs come out sorted by owner as _sample needs
        near = grid.spheres_within(grid.centers[a], float(grid.radii[a]))
        near = near[near != a]
        owners.append(np.full(near.size, a, dtype=np.int64))
        others.append(near)
    mask = np.zeros(grid.centers.shape[0], dtype=bool)
    mask[atoms] = True
    i = np.concatenate(owners) if owners else np.empty(0, dtype=np.int64)
    j = np.concatenate(others) if others else np.empty(0, dtype=np.int64)
    return _areas(grid, i, j, mask, n_points, refine_points)[0][atoms]


def _areas(
    grid: UniformGrid,
    i: np.ndarray,
    j: np.ndarray,
    atoms: np.ndarray,
    n_points: int,
    refine_points: int,
) -> tuple[np.ndarray, np.ndarray]:
    """(areas, refined mask): every selected atom sampled with `n_points`; those with a
    small non-zero area sampled again with `refine_points`."""
    if n_points < 2 or refine_points < 2:
        raise ValueError("at least 2 test points per atom are needed")
    areas = _sample(grid, i, j, atoms, n_points)
    refine = atoms & (areas > 0.0) & (areas < REFINE_BELOW)
    if refine_points > n_points and refine.any():
        areas[refine] = _sample(grid, i, j, refine, refine_points)[refine]
    return areas, refine


def _sample(
    grid: UniformGrid, i: np.ndarray, j: np.ndarray, atoms: np.ndarray, n_points: int
) -> np.ndarray:
    """SR areas of the selected atoms (others are returned as full spheres, unused)."""
    centers, radii = grid.centers, grid.radii
    n = centers.shape[0]
    if not atoms.all():
        mine = atoms[i]
        i, j = i[mine], j[mine]
    d_vec = centers[j] - centers[i]
    d = np.sqrt(np.einsum("ij,ij->i", d_vec, d_vec))
    pad = -n_points % 64  # whole 64-bit words, so rows OR together as uint64
    buried = np.zeros((n, (n_points + pad) // 64), dtype=np.uint64)  # bit set = test point buried
    # Identical centres: the larger (or, equal, the lower-index) sphere hides the other.
    coincident = d == 0.0
    hides = coincident & ((radii[j] > radii[i]) | ((radii[j] == radii[i]) & (j < i)))
    # A sphere wholly inside a neighbour is buried; a neighbour inside it buries nothing.
    inside = ~coincident & (d + radii[i] <= radii[j])
    buried[i[hides | inside]] = np.iinfo(np.uint64).max
    use = ~coincident & ~inside
    i, j, d_vec, d = i[use], j[use], d_vec[use], d[use]
    # float32: a point flips only when it lies within ~1e-7 of a cap edge
    normals = (d_vec / d[:, None]).astype(np.float32)
    cos_cap = ((radii[i] ** 2 + d**2 - radii[j] ** 2) / (2.0 * radii[i] * d)).astype(np.float32)
    unit_t = sphere_points(n_points).T.astype(np.float32)
    chunk = max(1, _CHUNK_ELEMENTS // n_points)
    for lo in range(0, i.size, chunk):
        hi = min(lo + chunk, i.size)
        inside_cap = (normals[lo:hi] @ unit_t) > cos_cap[lo:hi, None]
        if pad:
            inside_cap = np.pad(inside_cap, ((0, 0), (0, pad)))
        bits = np.packbits(inside_cap, axis=1).view(np.uint64)
        owners = i[lo:hi]
        # pairs are sorted by owner: OR the bit rows of each owner together
        first = np.flatnonzero(np.r_[True, owners[1:] != owners[:-1]])
        buried[owners[first]] |= np.bitwise_or.reduceat(bits, first, axis=0)
    n_buried = np.unpackbits(buried.view(np.uint8), axis=1, count=n_points).sum(axis=1)
    return 4.0 * np.pi * radii**2 * (n_points - n_buried) / n_points
