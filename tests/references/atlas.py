"""CPU reference of the occlusion atlas (render/lighting/ao/precomputed.py), from its
definition and the mathematics, sharing no code with it: the octahedral map (Cigolle et
al., JCGT 2014), the spherical Fibonacci directions, QuteMol's patch layout (texel centres
on the patch border), the baked values (brute force over every sphere, rays clipped as
everywhere else; texels inside other atoms or cut away are never seen) and the fill of
those unseen texels."""

from __future__ import annotations

import numpy as np
from sasprobe.render.lighting.settings import HARD_SHADOW, ray_epsilon

from tests.references.lighting import FAR, Occluders, occluded_visibility


def octa_decode(e: np.ndarray) -> np.ndarray:
    """(..., 2) in [-1, 1]^2 -> (..., 3) unit vectors."""
    e = np.asarray(e, dtype=np.float64)
    v = np.concatenate([e, (1.0 - np.abs(e).sum(axis=-1))[..., None]], axis=-1)
    lower = v[..., 2] < 0
    sign = np.where(v[..., :2] >= 0, 1.0, -1.0)
    folded = (1.0 - np.abs(v[..., 1::-1])) * sign
    v[..., :2] = np.where(lower[..., None], folded, v[..., :2])
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def octa_encode(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    p = v[..., :2] / np.abs(v).sum(axis=-1, keepdims=True)
    sign = np.where(p >= 0, 1.0, -1.0)
    return np.where((v[..., 2] < 0)[..., None], (1.0 - np.abs(p[..., ::-1])) * sign, p)


def directions(n: int) -> np.ndarray:
    """Spherical Fibonacci lattice: z_k = 1 - (2k + 1)/n, azimuth k times the golden angle."""
    k = np.arange(n)
    z = 1.0 - (2 * k + 1) / n
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    return np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])


def texel_normals(patch: int) -> np.ndarray:
    """(patch, patch, 3): the direction texel (i, j) (x = i, y = j) of a patch stands for."""
    i, j = np.meshgrid(np.arange(patch), np.arange(patch), indexing="xy")
    return octa_decode(np.stack([i, j], axis=-1) * (2.0 / (patch - 1)) - 1.0)


def points_kept(points: np.ndarray, culling) -> np.ndarray:
    """Whether each point survives the culling: on the kept side (a·x + b·y + c·z + d >= 0)
    of every clip plane and inside the navigation cube (what is drawn of a sphere)."""
    x = np.asarray(points, dtype=np.float64)
    kept = np.ones(x.shape[0], dtype=bool)
    for plane in culling.clip_planes:
        kept &= x @ plane[:3] + plane[3] >= 0
    if culling.nav_cube is not None:
        centre, half = culling.nav_cube
        kept &= np.all(np.abs(x - centre) <= half, axis=1)
    return kept


def bake_atom(
    atom: int, occ: Occluders, patch: int, n_directions: int, distance: float, sun=None, lamp=None
):
    """(accessibility, sun visibility, probe-light visibility, hidden) of one atom's patch,
    each (patch, patch): NaN where not computed (no `sun`, no `lamp`: (position, range))."""
    c, r = occ.centers[atom], occ.radii[atom]
    n = texel_normals(patch).reshape(-1, 3)
    x = c + r * n
    others = np.flatnonzero(~occ.culled & (np.arange(len(occ.radii)) != atom))
    inside = (
        np.linalg.norm(x[:, None, :] - occ.centers[others][None], axis=-1) < occ.radii[others][None]
    )
    hidden = inside.any(axis=1) | ~points_kept(
        x, occ.culling
    )  # never seen: inside another atom, or cut away
    o = x + n * ray_epsilon(x)[:, None]
    dirs = directions(n_directions)
    w = np.maximum(n @ dirs.T, 0.0)  # (texels, D)
    texel, k = np.nonzero(w > 0)
    vis = occluded_visibility(
        o[texel],
        dirs[k],
        0.0,
        distance,
        np.full(texel.size, atom),
        np.arange(len(occ.radii)),
        occ,
        HARD_SHADOW,
        False,
    )
    open_ = np.zeros_like(w)
    open_[texel, k] = vis
    ambient = (w * open_).sum(axis=1) / w.sum(axis=1)
    sun_vis = np.full(len(n), np.nan)
    if sun is not None:
        d = np.asarray(sun, dtype=np.float64) / np.linalg.norm(sun)
        facing = n @ d > 0
        sun_vis = np.zeros(len(n))
        sun_vis[facing] = occluded_visibility(
            o[facing],
            np.broadcast_to(d, o[facing].shape).copy(),
            0.0,
            FAR,
            np.full(facing.sum(), atom),
            np.arange(len(occ.radii)),
            occ,
            HARD_SHADOW,
            False,
        )
    lamp_vis = np.full(len(n), np.nan)
    if lamp is not None:
        position, reach = np.asarray(lamp[0], dtype=np.float64), float(lamp[1])
        to_light = position - o
        length = np.linalg.norm(to_light, axis=1)
        d = to_light / length[:, None]
        lamp_vis = np.where(np.einsum("ij,ij->i", n, d) > 0, 1.0, 0.0)
        lamp_vis[np.linalg.norm(position - x, axis=1) > reach] = 1.0
        go = np.flatnonzero((lamp_vis == 1.0) & (np.linalg.norm(position - x, axis=1) <= reach))
        lamp_vis[go] = occluded_visibility(
            o[go],
            d[go],
            0.0,
            length[go],
            np.full(go.size, atom),
            np.arange(len(occ.radii)),
            occ,
            HARD_SHADOW,
            False,
        )
    shape = (patch, patch)
    return (
        ambient.reshape(shape),
        sun_vis.reshape(shape),
        lamp_vis.reshape(shape),
        hidden.reshape(shape),
    )


def fill_hidden(values: np.ndarray, hidden: np.ndarray, rounds: int = 2) -> np.ndarray:
    """Each round, a hidden texel takes the mean of the non-hidden texels among its 3 x 3
    neighbours in the patch (the patch's edge clamps); still hidden after the last: 0."""
    v = np.where(hidden, np.nan, values).astype(np.float64)
    p = v.shape[0]
    for _ in range(rounds):
        padded = np.pad(v, 1, mode="edge")
        stack = np.stack(
            [
                padded[1 + dy : 1 + dy + p, 1 + dx : 1 + dx + p]
                for dy in (-1, 0, 1)
                for dx in (-1, 0, 1)
            ]
        )
        count = np.sum(~np.isnan(stack), axis=0)
        mean = np.where(count > 0, np.nansum(stack, axis=0) / np.maximum(count, 1), np.nan)
        v = np.where(np.isnan(v), mean, v)
    return np.nan_to_num(v, nan=0.0)


def bilinear(atlas: np.ndarray, x: float, y: float) -> np.ndarray:
    """GL's linear filter at texel coordinates (x, y) (texel centres at .5)."""
    x0, y0 = int(np.floor(x - 0.5)), int(np.floor(y - 0.5))
    fx, fy = x - 0.5 - x0, y - 0.5 - y0
    h, w = atlas.shape[:2]
    at = lambda i, j: atlas[min(max(j, 0), h - 1), min(max(i, 0), w - 1)]  # noqa: E731
    return (
        (1 - fx) * (1 - fy) * at(x0, y0)
        + fx * (1 - fy) * at(x0 + 1, y0)
        + (1 - fx) * fy * at(x0, y0 + 1)
        + fx * fy * at(x0 + 1, y0 + 1)
    )
