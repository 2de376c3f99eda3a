"""The occlusion atlas's geometry, the same for every patch (render/lighting/ao/precomputed.py):
the ray directions (a spherical Fibonacci lattice, in clusters of nearby ones), each
texel's direction (the octahedral map) and which texels face which direction."""

from __future__ import annotations

import math

import numpy as np

# Directions side by side in one SIMD pass (llvmpipe's 256-bit vectors): nearby ones skip and
# stop together.
CLUSTER = 8


def fibonacci_directions(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere: z = 1 - (2k + 1)/n, the azimuth
    turning by the golden angle pi (3 - sqrt 5) per point (spherical Fibonacci lattice)."""
    k = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * k + 1.0) / n
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def texel_normals(patch: int) -> np.ndarray:
    """(P*P, 4) float32: texel (i, j)'s direction at row i + P j, the octahedral decode
    (Cigolle et al., JCGT 2014) of 2 (i, j) / (P - 1) - 1, as shaders/octahedral.glsl; the
    same for every patch, uploaded once for the bake (shaders/atlas_bake_buffers.glsl)."""
    j, i = np.divmod(np.arange(patch * patch), patch)
    e = np.column_stack([i, j]).astype(np.float64) * (2.0 / (patch - 1)) - 1.0
    v = np.column_stack([e, 1.0 - np.abs(e).sum(axis=1)])
    lower = v[:, 2] < 0
    sign = np.where(v[:, :2] >= 0, 1.0, -1.0)
    v[lower, :2] = ((1.0 - np.abs(v[:, 1::-1])) * sign)[lower]
    out = np.zeros((patch * patch, 4), dtype=np.float32)
    out[:, :3] = v / np.linalg.norm(v, axis=1, keepdims=True)
    return out


def facing_masks(
    normals: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which texels face which direction (n.d > 0 in float32, as the shaders compute it), as
    bits both ways — (D, ceil(P^2 / 32)) uint32, bit t % 32 of word t / 32 of row d when
    texel t faces direction d (the rays step's), and its transpose (P^2, ceil(D / 32)), bit
    d % 32 of word d / 32 of row t (the sums step's): one table, so both steps agree — and
    each texel's sum of n.d over the directions it faces (the weight of all its rays)."""
    dots = directions[:, :3].astype(np.float32) @ normals[:, :3].astype(np.float32).T  # (D, P^2)
    faces = dots > 0
    return (
        bit_rows(faces),
        bit_rows(faces.T),
        np.where(faces, dots.astype(np.float64), 0.0).sum(axis=0),
    )


def bit_rows(flags: np.ndarray) -> np.ndarray:
    """(R, C) bool -> (R, ceil(C / 32)) uint32: bit c % 32 of word c / 32 set where flags[r, c]."""
    rows, columns = flags.shape
    padded = np.zeros((rows, -(-columns // 32) * 32), dtype=np.uint64)
    padded[:, :columns] = flags
    words = padded.reshape(rows, -1, 32) << np.arange(32, dtype=np.uint64)
    return words.sum(axis=2).astype(np.uint32)


def clustered(directions: np.ndarray, size: int = CLUSTER) -> np.ndarray:
    """The same directions in groups of `size` nearby ones (recursive halving along the
    widest axis): the bake's invocations of a direction run side by side in groups, and a
    group of close directions faces away from, and is blocked by, much the same. The sum
    over directions is unchanged by their order."""
    groups: list[np.ndarray] = []

    def split(index: np.ndarray) -> None:
        if index.size <= size:
            groups.append(index)
            return
        left = (math.ceil(index.size / size) // 2) * size
        points = directions[index]
        axis = int(np.argmax(points.max(axis=0) - points.min(axis=0)))
        order = index[np.argsort(points[:, axis], kind="stable")]
        split(order[:left])
        split(order[left:])

    split(np.arange(directions.shape[0]))
    return directions[np.concatenate(groups)]
