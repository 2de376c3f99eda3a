"""CPU references (numpy, float64, vectorised) for every GPU lighting term (test code:
it ships with the tests, not in the wheel).

They take the same inputs as the GPU passes: G-buffer arrays (world positions, normals,
atom ids; any image shape) and the occluding spheres with their culled flags and clip
state, and follow the same definitions (documented in render/shaders/grid_traversal.glsl and
render/lighting/settings.py) without sharing code with the shaders:

- `light_visibility`: hard shadows and Parker soft shadows, directional or point light,
  brute force over all spheres;
- `analytic_ao`: Quilez's sphere occlusion over each atom's K nearest neighbours;
- `monte_carlo_ao`: cosine-weighted ray-traced accessibility (stratified samples);
- `raycast_gbuffer`: a brute-force primary ray caster with clip caps.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sasprobe.render.gl.targets import ATOM_BACKGROUND, ATOM_PROBE
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.settings import (
    HARD_SHADOW,
    DirectionalLight,
    PointLight,
    SoftShadow,
    ray_epsilon,
)

FAR = 1e30
_CHUNK_ELEMENTS = 1 << 21  # rays × spheres per vectorised block (~50 MB of temporaries)


@dataclass
class Occluders:
    """The spheres that shadow and occlude: vdW spheres, culled flags, clipping, the probe."""

    centers: np.ndarray  # (N, 3) Å
    radii: np.ndarray  # (N,) vdW, Å
    culled: np.ndarray = None  # (N,) bool
    culling: Culling = field(default_factory=Culling)
    probe: np.ndarray | None = None  # (4,) centre, radius
    probe_reach: float = np.inf  # Å: the probe's share of the AO is windowed to 0 there

    def __post_init__(self) -> None:
        self.centers = np.asarray(self.centers, dtype=np.float64).reshape(-1, 3)
        self.radii = np.asarray(self.radii, dtype=np.float64).reshape(-1)
        if self.culled is None:
            self.culled = self.culling.culled_atoms(self.centers, self.radii)
        self.centre_clipped = self.culling.centre_clipped(self.centers)

    @classmethod
    def of(cls, gpu_grid) -> Occluders:
        """The same occluders a UploadedGrid holds (its culled flags, clipping and probe)."""
        probe = np.asarray(gpu_grid.probe_sphere, dtype=np.float64)
        return cls(
            gpu_grid.grid.centers,
            gpu_grid.vdw_radii,
            gpu_grid.culled_mask.copy(),
            gpu_grid.culling,
            probe if probe[3] > 0 else None,
            gpu_grid.probe_reach,
        )


# ------------------------------------------------------------------ rays and clipping
def clip_rays(origins, directions, t0, t1, culling: Culling):
    """Kept interval [t0, t1] of each ray after clip planes and cube, and the outward normal
    of the cut each ray enters through (zero if none). Empty where t0 >= t1."""
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    t0 = np.array(np.broadcast_to(t0, o.shape[:-1]), dtype=np.float64)
    t1 = np.array(np.broadcast_to(t1, o.shape[:-1]), dtype=np.float64)
    entry = np.zeros_like(o)
    for plane in culling.clip_planes:
        n, w = plane[:3], plane[3]
        s = o @ n + w
        dn = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -s / dn
        enter = (dn > 0) & (t > t0)
        t0 = np.where(enter, t, t0)
        entry[enter] = -n
        t1 = np.where(dn < 0, np.minimum(t1, t), t1)
        t1 = np.where((dn == 0) & (s < 0), -np.inf, t1)
    box = culling.cube_box
    if box is not None:
        lo, hi = box
        for a in range(3):
            da = d[..., a]
            parallel = da == 0
            with np.errstate(divide="ignore", invalid="ignore"):
                ta = (lo[a] - o[..., a]) / da
                tb = (hi[a] - o[..., a]) / da
            t_in = np.where(parallel, -np.inf, np.minimum(ta, tb))
            t_out = np.where(parallel, np.inf, np.maximum(ta, tb))
            outside = parallel & ((o[..., a] < lo[a]) | (o[..., a] > hi[a]))
            enter = t_in > t0
            t0 = np.where(enter, t_in, t0)
            entry[enter] = 0.0
            entry[enter & (da > 0), a] = -1.0
            entry[enter & (da < 0), a] = 1.0
            t1 = np.where(outside, -np.inf, np.minimum(t1, t_out))
    return t0, t1, entry


def _smooth_visibility(b, r_in, r_out):
    """0 inside r_in, 1 from r_out on, smoothstep between (hard where r_in == r_out)."""
    width = np.where(r_out > r_in, r_out - r_in, 1.0)
    x = np.clip((b - r_in) / width, 0.0, 1.0)
    smooth = x * x * (3.0 - 2.0 * x)
    return np.where(b < r_in, 0.0, np.where(b >= r_out, 1.0, smooth))


def segment_visibility(o, d, t0, t1, skip, centers, radii, ids, soft: SoftShadow):
    """Visibility (0..1) of segments o + t d, t in [t0, t1] (empty where t0 >= t1), against
    spheres (centers, radii) labelled `ids`: the minimum over them of the Parker factor, a
    ray's own `skip` id excluded."""
    r = o.shape[0]
    vis = np.ones(r)
    if centers.shape[0] == 0:
        return vis
    live = t0 < t1
    chunk = max(1, _CHUNK_ELEMENTS // centers.shape[0])
    for a in range(0, r, chunk):
        sl = slice(a, min(r, a + chunk))
        f = centers[None, :, :] - o[sl, None, :]
        t = np.clip(np.einsum("rmk,rk->rm", f, d[sl]), t0[sl, None], t1[sl, None])
        with np.errstate(
            invalid="ignore"
        ):  # a segment culled whole (t1 = -inf) gives NaN: `live` drops it
            q = f - t[..., None] * d[sl, None, :]
        b2 = np.einsum("rmk,rmk->rm", q, q)
        if soft.inner == soft.outer == 0.0:  # hard: blocked where b < r
            v = np.where(b2 < radii[None, :] ** 2, 0.0, 1.0)
        else:
            s = np.clip(t / soft.growth, 0.0, 1.0) if soft.growth > 0 else 1.0
            v = _smooth_visibility(
                np.sqrt(b2), np.maximum(radii + soft.inner * s, 0.0), radii + soft.outer * s
            )
        v[ids[None, :] == skip[sl, None]] = 1.0
        vis[sl] = np.where(live[sl], v.min(axis=1), 1.0)
    return vis


def occluded_visibility(
    o, d, t0, t1, skip, candidates, occ: Occluders, soft: SoftShadow, with_probe
):
    """Visibility of segments against the candidate atoms (culled ones excluded, each
    segment clipped to what the planes and cube keep) and, where `with_probe`, the probe
    sphere (never clipped)."""
    kept0, kept1, _ = clip_rays(o, d, t0, t1, occ.culling)
    ids = candidates[~occ.culled[candidates]]
    vis = segment_visibility(o, d, kept0, kept1, skip, occ.centers[ids], occ.radii[ids], ids, soft)
    with_probe = np.broadcast_to(with_probe, vis.shape)
    if occ.probe is not None and np.any(with_probe):
        t0 = np.broadcast_to(t0, vis.shape)
        t1 = np.where(with_probe, np.broadcast_to(t1, vis.shape), -np.inf)
        probe = segment_visibility(
            o, d, t0, t1, skip, occ.probe[None, :3], occ.probe[3:4], np.array([ATOM_PROBE]), soft
        )
        vis = np.minimum(vis, probe)
    return vis


def _flatten(positions, normals, atom_ids):
    """G-buffer layers as flat arrays: (image shape, ids, float64 positions, unit normals)."""
    atom_ids = np.asarray(atom_ids)
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    n = n / np.maximum(np.linalg.norm(n, axis=1), 1e-30)[:, None]
    return atom_ids.shape, atom_ids.reshape(-1), p, n


# ------------------------------------------------------------------ shadows
def light_visibility(
    positions,
    normals,
    atom_ids,
    light: DirectionalLight | PointLight,
    occ: Occluders,
    soft: SoftShadow = HARD_SHADOW,
) -> np.ndarray:
    """Visibility of a light (0..1) at G-buffer pixels; 1 on background. Pixels facing away
    from the light get 0 (their own atom blocks it). For a point light, pixels farther than
    its radius get 1 (unlit anyway, not traced) and the probe sphere, which holds the light,
    does not occlude it."""
    shape, ids, p, n = _flatten(positions, normals, atom_ids)
    out = np.ones(ids.shape[0])
    pick = np.flatnonzero(ids != ATOM_BACKGROUND)
    p, n, ids = p[pick], n[pick], ids[pick]
    o = p + n * ray_epsilon(p)[:, None]
    if isinstance(light, DirectionalLight):
        d = np.broadcast_to(light.unit(), o.shape).copy()
        t1 = np.full(o.shape[0], FAR)
        traced = np.ones(o.shape[0], dtype=bool)
        with_probe = ids != ATOM_PROBE
    else:
        to_light = np.asarray(light.position, dtype=np.float64) - o
        t1 = np.linalg.norm(to_light, axis=1)
        d = to_light / np.maximum(t1, 1e-30)[:, None]
        traced = np.linalg.norm(np.asarray(light.position) - p, axis=1) <= light.radius
        with_probe = np.zeros(o.shape[0], dtype=bool)
    facing = np.einsum("ij,ij->i", n, d) > 0
    vis = np.where(traced, 0.0, 1.0)
    go = traced & facing
    vis[go] = occluded_visibility(
        o[go],
        d[go],
        0.0,
        t1[go],
        ids[go],
        np.arange(occ.centers.shape[0]),
        occ,
        soft,
        with_probe[go],
    )
    out[pick] = vis
    return out.reshape(shape)


# ------------------------------------------------------------------ ambient occlusion
def sphere_occlusion(p, n, centers, radii):
    """Quilez's sphere occlusion: cos(theta) (r / l)^2, clamped to [0, 1] (exact for a
    sphere wholly above the horizon)."""
    diff = centers - p
    length = np.sqrt(np.einsum("...k,...k->...", diff, diff))
    cos = np.einsum("...k,...k->...", diff, n) / length
    return np.clip(np.maximum(cos, 0.0) * (radii / length) ** 2, 0.0, 1.0)


def probe_occlusion(p, n, probe, reach):
    """The probe's share: its sphere occlusion times (1 - (l / reach)^4)^2 clipped to 0
    beyond `reach` (the probe light's window)."""
    x = np.linalg.norm(p - probe[:3], axis=-1) / reach
    return sphere_occlusion(p, n, probe[:3], probe[3]) * np.clip(1.0 - x**4, 0.0, 1.0) ** 2


def analytic_ao(
    positions,
    normals,
    atom_ids,
    occ: Occluders,
    neighbours: np.ndarray,
    k: int,
    probe_neighbour_ids: np.ndarray | None = None,
) -> np.ndarray:
    """Accessibility 1 - occlusion from each pixel's atom's first k neighbours (rows of
    `neighbours`, -1 padded; culled ones and those with a clipped centre skipped) and the
    probe, combined multiplicatively (prod(1 - occ_i), so overlapping occluders are not
    counted twice into negative light). Probe pixels use `probe_neighbour_ids`. 1 on
    background."""
    shape, ids, p, n = _flatten(positions, normals, atom_ids)
    out = np.ones(ids.shape[0])
    atoms = np.flatnonzero(ids >= 0)
    lists = np.asarray(neighbours)[ids[atoms], :k]
    out[atoms] = _product_of_accessibility(p[atoms], n[atoms], lists, occ)
    if occ.probe is not None:
        out[atoms] *= 1.0 - probe_occlusion(p[atoms], n[atoms], occ.probe, occ.probe_reach)
        on_probe = np.flatnonzero(ids == ATOM_PROBE)
        if on_probe.size and probe_neighbour_ids is not None:
            lists = np.broadcast_to(
                np.asarray(probe_neighbour_ids)[:k],
                (on_probe.size, min(k, len(probe_neighbour_ids))),
            )
            out[on_probe] = _product_of_accessibility(p[on_probe], n[on_probe], lists, occ)
    return out.reshape(shape)


def _product_of_accessibility(p, n, lists, occ: Occluders):
    usable = (
        (lists >= 0) & ~occ.culled[np.maximum(lists, 0)] & ~occ.centre_clipped[np.maximum(lists, 0)]
    )
    safe = np.maximum(lists, 0)
    occlusion = sphere_occlusion(p[:, None, :], n[:, None, :], occ.centers[safe], occ.radii[safe])
    return np.prod(np.where(usable, 1.0 - occlusion, 1.0), axis=1)


def cosine_directions(normals: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions about unit normals (…, 3) from u in [0,1)^2 (…, S, 2)."""
    r = np.sqrt(u[..., 0])
    phi = 2.0 * np.pi * u[..., 1]
    local = np.stack(
        [r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - u[..., 0]))], axis=-1
    )
    # any orthonormal frame will do: build one from the axis least aligned with n
    n = normals[..., None, :]
    helper = np.where(
        np.abs(n[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    )
    t1 = np.cross(helper, n)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    t2 = np.cross(n, t1)
    return local[..., :1] * t1 + local[..., 1:2] * t2 + local[..., 2:3] * n


def stratified_unit_square(count_side: int, rng: np.random.Generator, batch: int) -> np.ndarray:
    """(batch, count_side², 2) jittered-stratified points in [0, 1)^2, one set per batch item."""
    i, j = np.meshgrid(np.arange(count_side), np.arange(count_side), indexing="ij")
    cells = np.stack([i.ravel(), j.ravel()], axis=-1).astype(np.float64)
    return (cells[None] + rng.random((batch, cells.shape[0], 2))) / count_side


def monte_carlo_ao(
    positions,
    normals,
    atom_ids,
    occ: Occluders,
    distance: float,
    samples_side: int,
    rng: np.random.Generator,
    grid=None,
) -> np.ndarray:
    """Cosine-weighted accessibility: the fraction of rays from each pixel (samples_side²
    jittered-stratified directions) that travel `distance` Å without meeting a sphere
    (culled ones and the pixel's own atom excluded; the probe included except on its own
    pixels). `grid` (the UniformGrid) narrows the spheres to those within reach. 1 on
    background."""
    shape, ids, p_all, n_all = _flatten(positions, normals, atom_ids)
    out = np.ones(ids.shape[0])
    everyone = np.arange(occ.centers.shape[0])
    for atom in np.unique(ids[ids != ATOM_BACKGROUND]):
        pix = np.flatnonzero(ids == atom)
        p, n = p_all[pix], n_all[pix]
        if grid is not None:
            center, radius = (
                (occ.probe[:3], occ.probe[3])
                if atom == ATOM_PROBE
                else (occ.centers[atom], occ.radii[atom])
            )
            reach = (
                distance + radius + np.max(np.linalg.norm(p - center, axis=1) - radius, initial=0.0)
            )
            candidates = grid.spheres_within(center, reach)
        else:
            candidates = everyone
        u = stratified_unit_square(samples_side, rng, pix.size)
        dirs = cosine_directions(n, u).reshape(-1, 3)
        o = np.repeat(p + n * ray_epsilon(p)[:, None], u.shape[1], axis=0)
        skip = np.full(o.shape[0], atom)
        vis = occluded_visibility(
            o, dirs, 0.0, distance, skip, candidates, occ, HARD_SHADOW, atom != ATOM_PROBE
        )
        out[pix] = vis.reshape(pix.size, -1).mean(axis=1)
    return out.reshape(shape)


# ------------------------------------------------------------------ primary rays
def camera_rays(view: np.ndarray, proj: np.ndarray, width: int, height: int):
    """World-space origins and unit directions through pixel centres; row 0 = bottom row
    (OpenGL window coordinates), shape (H, W, 3)."""
    inv = np.linalg.inv(np.asarray(proj, dtype=np.float64) @ np.asarray(view, dtype=np.float64))
    x = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    y = (np.arange(height) + 0.5) / height * 2.0 - 1.0
    gx, gy = np.meshgrid(x, y)
    near = np.stack([gx, gy, -np.ones_like(gx), np.ones_like(gx)], axis=-1) @ inv.T
    far = np.stack([gx, gy, np.ones_like(gx), np.ones_like(gx)], axis=-1) @ inv.T
    near = near[..., :3] / near[..., 3:]
    far = far[..., :3] / far[..., 3:]
    eye = np.linalg.inv(np.asarray(view, dtype=np.float64))[:3, 3]
    d = far - eye
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return np.broadcast_to(eye, d.shape).copy(), d


def raycast_gbuffer(view, proj, width, height, occ: Occluders):
    """Brute-force G-buffer: (position (H,W,3), normal (H,W,3), atom id (H,W)), row 0 at the
    bottom; spheres cut by clip planes and the cube show caps with the cut's normal."""
    o, d = camera_rays(view, proj, width, height)
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    t0, t1, entry = clip_rays(o, d, 0.0, FAR, occ.culling)
    ids = np.flatnonzero(~occ.culled)
    centers, radii = occ.centers[ids], occ.radii[ids]
    if occ.probe is not None:  # never clipped: its rays keep [0, FAR]
        centers = np.vstack([centers, occ.probe[:3]])
        radii = np.append(radii, occ.probe[3])
        ids = np.append(ids, ATOM_PROBE)
    clipped = ids != ATOM_PROBE
    best_t = np.full(o.shape[0], np.inf)
    best = np.full(o.shape[0], -1, dtype=np.int64)
    best_cap = np.zeros(o.shape[0], dtype=bool)
    chunk = max(1, _CHUNK_ELEMENTS // max(1, centers.shape[0]))
    for a in range(0, o.shape[0], chunk):
        sl = slice(a, min(o.shape[0], a + chunk))
        f = o[sl, None, :] - centers[None]
        b = np.einsum("rmk,rk->rm", f, d[sl])
        q = f - b[..., None] * d[sl, None, :]
        disc = radii[None] ** 2 - np.einsum("rmk,rmk->rm", q, q)
        h = np.sqrt(np.maximum(disc, 0.0))
        t_in, t_out = -b - h, -b + h
        lo = np.where(clipped[None, :], t0[sl, None], 0.0)
        hi = np.where(clipped[None, :], t1[sl, None], FAR)
        t = np.maximum(t_in, lo)
        ok = (disc >= 0) & (t <= np.minimum(t_out, hi)) & (clipped[None, :] | (t_in >= 0.0))
        t = np.where(ok, t, np.inf)
        k = np.argmin(t, axis=1)
        rows = np.arange(k.size)
        best_t[sl] = t[rows, k]
        best[sl] = np.where(np.isfinite(best_t[sl]), ids[k], ATOM_BACKGROUND)
        best_cap[sl] = t_in[rows, k] < lo[rows, k]
    hit = best != ATOM_BACKGROUND
    position = np.zeros_like(o)
    position[hit] = o[hit] + best_t[hit, None] * d[hit]
    normal = np.zeros_like(o)
    centre_of = np.where(
        best[:, None] == ATOM_PROBE,
        occ.probe[:3] if occ.probe is not None else 0.0,
        occ.centers[np.maximum(best, 0)],
    )
    radius_of = np.where(
        best == ATOM_PROBE,
        occ.probe[3] if occ.probe is not None else 1.0,
        occ.radii[np.maximum(best, 0)],
    )
    normal[hit] = (position[hit] - centre_of[hit]) / radius_of[hit, None]
    cap = hit & best_cap
    normal[cap] = entry[cap]
    shape = (height, width)
    return (
        position.reshape(*shape, 3),
        normal.reshape(*shape, 3),
        best.reshape(shape).astype(np.int32),
    )


# ------------------------------------------------------------------ edge cueing
def view_depths(positions, atom_ids, view) -> np.ndarray:
    """View-space depth (Å, positive) per pixel; inf on background."""
    p = np.asarray(positions, dtype=np.float64)
    depth = -(p @ np.asarray(view)[2, :3] + np.asarray(view)[2, 3])
    return np.where(np.asarray(atom_ids) == ATOM_BACKGROUND, np.inf, depth)


def edge_cueing(depth: np.ndarray, atom_ids: np.ndarray, settings) -> np.ndarray:
    """QuteMol contour lines and halos from view depths (inf = background) and atom ids
    (only other atoms count); 1 = untouched. Same definition as shaders/edge_cueing.comp,
    by whole-image shifts."""
    h, w = depth.shape
    line = np.zeros((h, w))
    halo = np.zeros((h, w))
    reach = max(
        settings.line_width if settings.contours else 0.0,
        settings.halo_radius if settings.halos else 0.0,
    )
    r = int(np.ceil(reach))
    padded = np.pad(depth, r, mode="constant", constant_values=np.inf)
    padded_ids = np.pad(np.asarray(atom_ids), r, mode="constant", constant_values=ATOM_BACKGROUND)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            front = padded[r + dy : r + dy + h, r + dx : r + dx + w]
            other = padded_ids[r + dy : r + dy + h, r + dx : r + dx + w] != atom_ids
            dist = np.hypot(dx, dy)
            with np.errstate(invalid="ignore"):
                gap = np.where(
                    np.isinf(front) | ~other, -np.inf, depth - front
                )  # inf - finite = inf: behind
            if settings.contours and dist <= settings.line_width:
                strength = np.clip(gap / settings.line_threshold - 1.0, 0.0, 1.0)
                line = np.maximum(line, np.where(gap > settings.line_threshold, strength, 0.0))
            if settings.halos and dist <= settings.halo_radius:
                strength = (1.0 - dist / settings.halo_radius) * np.clip(
                    gap / settings.halo_depth, 0.0, 1.0
                )
                halo = np.maximum(halo, np.where(gap > 0, strength, 0.0))
    return (1.0 - line) * (1.0 - settings.halo_strength * halo)
