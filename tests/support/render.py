"""Shared by the render tests: an independent numpy reference ray caster (brute force over
spheres, float64) for a given view/projection, and small helpers. The GL context and the
structures are fixtures in conftest.py."""

from __future__ import annotations

import numpy as np


def pixel_rays(
    view: np.ndarray, proj: np.ndarray, width: int, height: int
) -> tuple[np.ndarray, np.ndarray]:
    """Eye position and unit world directions (H, W, 3) through pixel centres; row 0 = top."""
    inv_vp = np.linalg.inv(proj @ view)
    eye = np.linalg.inv(view)[:3, 3]
    xs = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    ys = 1.0 - (np.arange(height) + 0.5) / height * 2.0
    ndc = np.stack(np.meshgrid(xs, ys), axis=-1)  # (H, W, 2)
    far = (
        np.concatenate([ndc, np.ones(ndc.shape[:2] + (2,))], axis=-1) @ inv_vp.T
    )  # points on the far plane
    far = far[..., :3] / far[..., 3:]
    d = far - eye
    return eye, d / np.linalg.norm(d, axis=-1, keepdims=True)


def reference_cast(view, proj, width, height, centers, radii, ids, planes=(), chunk=64):
    """Closest visible point of spheres cut by half-spaces (a·x + d >= 0 kept), per pixel.

    Returns atom_id (H, W) int (-1 background), position (H, W, 3), normal (H, W, 3),
    cap (H, W) bool (the point lies on a plane). Brute force: every pixel against every sphere.
    `planes`: rows (a, b, c, d), none by default.
    """
    eye, dirs = pixel_rays(view, proj, width, height)
    d = dirs.reshape(-1, 3)
    n_px = d.shape[0]
    best_t = np.full(n_px, np.inf)
    best_id = np.full(n_px, -1, dtype=np.int64)
    best_plane = np.full(n_px, -1, dtype=np.int64)
    best_sphere = np.full(n_px, -1, dtype=np.int64)
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 4)
    s_dist = planes[:, :3] @ eye + planes[:, 3]  # signed distance of the eye, per plane
    dn = d @ planes[:, :3].T  # (P, n_planes)
    for start in range(0, len(centers), chunk):
        c = centers[start : start + chunk]
        r = radii[start : start + chunk]
        oc = c - eye  # (K, 3)
        b = d @ oc.T  # (P, K)
        disc = b * b - (np.einsum("ij,ij->i", oc, oc) - r * r)[None, :]
        hit = disc >= 0
        sq = np.sqrt(np.where(hit, disc, 0.0))
        t0, t1 = b - sq, b + sq
        entry_plane = np.full(t0.shape, -1, dtype=np.int64)
        for k in range(planes.shape[0]):
            with np.errstate(divide="ignore", invalid="ignore"):
                tp = (-s_dist[k] / dn[:, k])[:, None]
            entering = (dn[:, k] > 0)[:, None]
            leaving = (dn[:, k] < 0)[:, None]
            raise_t0 = entering & (tp > t0)
            t0 = np.where(raise_t0, tp, t0)
            entry_plane = np.where(raise_t0, k, entry_plane)
            t1 = np.where(leaving, np.minimum(t1, tp), t1)
            parallel_out = ((dn[:, k] == 0) & (s_dist[k] < 0))[:, None]
            hit &= ~parallel_out
        hit &= (t0 <= t1) & (t0 > 0)
        t = np.where(hit, t0, np.inf)
        k_best = np.argmin(t, axis=1)
        t_best = t[np.arange(n_px), k_best]
        better = t_best < best_t
        best_t[better] = t_best[better]
        best_id[better] = ids[start + k_best[better]]
        best_sphere[better] = start + k_best[better]
        best_plane[better] = entry_plane[np.arange(n_px), k_best][better]
    covered = np.isfinite(best_t)
    pos = np.zeros((n_px, 3))
    pos[covered] = eye + best_t[covered, None] * d[covered]
    nrm = np.zeros((n_px, 3))
    cap = covered & (best_plane >= 0)
    surf = covered & ~cap
    nrm[surf] = (pos[surf] - centers[best_sphere[surf]]) / radii[best_sphere[surf], None]
    nrm[cap] = -planes[best_plane[cap], :3]
    shape = (height, width)
    return (
        best_id.reshape(shape),
        pos.reshape(shape + (3,)),
        nrm.reshape(shape + (3,)),
        cap.reshape(shape),
    )


def edge_mask(ids: np.ndarray) -> np.ndarray:
    """Pixels whose id differs from a 4-neighbour: silhouettes and sphere-sphere seams."""
    edge = np.zeros(ids.shape, dtype=bool)
    diff_v = ids[1:, :] != ids[:-1, :]
    diff_h = ids[:, 1:] != ids[:, :-1]
    edge[1:, :] |= diff_v
    edge[:-1, :] |= diff_v
    edge[:, 1:] |= diff_h
    edge[:, :-1] |= diff_h
    return edge
