"""Screen rectangles: what a sphere, a capsule, points or a set of atoms can cover, and
the few operations the frame planner needs on them (render/frame_planner.py).

Rectangles are (x, y, width, height) in pixels with y up (GL's window and image
coordinates), clamped to the frame; None is an empty one.
"""

from __future__ import annotations

import numpy as np

Rect = tuple[int, int, int, int]


def sphere_rect(
    center, radius: float, viewproj: np.ndarray, size: tuple[int, int], margin: int = 2
) -> Rect | None:
    """Pixels a sphere can cover: the bounding box of its enclosing cube's eight corners
    projected (the cube holds the sphere, so its image holds the sphere's), grown by
    `margin`. The whole frame when a corner lies behind the eye; None when off screen."""
    return points_rect(_cube_corners(center, radius), viewproj, size, margin)


def capsule_rect(
    a, b, radius: float, viewproj: np.ndarray, size: tuple[int, int], margin: int = 2
) -> Rect | None:
    """Pixels a capsule (the segment a-b swept by a sphere) can cover: the bounding box of
    the corners of both end spheres' cubes projected (the capsule lies in their convex
    hull, and so does its image), grown by `margin`; as sphere_rect otherwise."""
    return points_rect(
        np.vstack([_cube_corners(a, radius), _cube_corners(b, radius)]), viewproj, size, margin
    )


def shadow_rect(
    center, radius: float, away, bound: tuple[np.ndarray, float], viewproj, size
) -> Rect | None:
    """Pixels the shadow of a sphere cast along `away` (unit) can fall on: the capsule from
    the sphere to where that line leaves `bound` (centre, radius: a sphere holding whatever
    the shadow can fall on), as wide as the sphere."""
    w = np.asarray(center, dtype=np.float64) - bound[0]
    along = float(w @ away)
    disc = along * along - float(w @ w) + (bound[1] + radius) ** 2
    # The line leaves the sphere where |w + s away| = bound radius + radius.
    length = max(np.sqrt(disc) - along, 0.0) if disc > 0 else 0.0
    return capsule_rect(center, center + length * away, radius, viewproj, size)


_CORNERS = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])


def _cube_corners(center, radius: float) -> np.ndarray:
    return np.asarray(center, dtype=np.float64).reshape(1, 3) + float(radius) * _CORNERS


def points_rect(
    points: np.ndarray, viewproj: np.ndarray, size: tuple[int, int], margin: int
) -> Rect | None:
    """The bounding box of points (N x 3, world) projected, grown by `margin`; the whole
    frame when one lies behind the eye, None when the box is off screen."""
    clip = (
        np.column_stack([points, np.ones(len(points))]) @ np.asarray(viewproj, dtype=np.float64).T
    )
    if np.any(clip[:, 3] <= 1e-9):
        return full_rect(size)
    return ndc_rect(clip[:, :2] / clip[:, 3:4], size, margin)


def ndc_rect(ndc: np.ndarray, size: tuple[int, int], margin: int) -> Rect | None:
    """The bounding box of points in normalised device coordinates (N x 2), in pixels,
    grown by `margin` and clamped to the frame."""
    w, h = size
    x0, y0 = np.floor((ndc.min(axis=0) * 0.5 + 0.5) * (w, h)).astype(int) - margin
    x1, y1 = np.ceil((ndc.max(axis=0) * 0.5 + 0.5) * (w, h)).astype(int) + margin
    return clamp_rect((int(x0), int(y0), int(x1 - x0), int(y1 - y0)), size)


def atoms_rect(
    positions: np.ndarray, radius: float, viewproj: np.ndarray, size: tuple[int, int]
) -> Rect | None:
    """Pixels spheres of at most `radius` around `positions` can cover (the whole frame when
    one reaches the eye's plane). A point moved by d, |d| <= r, moves in clip space by at
    most r |row| per row of viewproj, so its x / w by at most r (|x row| + |x/w| |w row|) /
    (w - r |w row|) (y alike): each centre's box, one projection for all."""
    if len(positions) == 0:
        return None
    viewproj = np.asarray(viewproj, dtype=np.float64)
    clip = np.asarray(positions, dtype=np.float64) @ viewproj[:, :3].T + viewproj[:, 3]
    rows = np.linalg.norm(viewproj[:, :3], axis=1) * radius
    depth = clip[:, 3] - rows[3]
    if depth.min() <= 1e-9:
        return full_rect(size)
    ndc = clip[:, :2] / clip[:, 3:4]
    reach = (rows[:2] + np.abs(ndc) * rows[3]) / depth[:, None]
    return ndc_rect(np.vstack([(ndc - reach).min(axis=0), (ndc + reach).max(axis=0)]), size, 1)


def intersect_rect(a: Rect | None, b: Rect | None) -> Rect | None:
    if a is None or b is None:
        return None
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[0] + a[2], b[0] + b[2]), min(a[1] + a[3], b[1] + b[3])
    return (x0, y0, x1 - x0, y1 - y0) if x1 > x0 and y1 > y0 else None


def clamp_rect(rect: Rect | None, size: tuple[int, int]) -> Rect | None:
    if rect is None:
        return None
    x, y, rw, rh = rect
    x0, y0 = max(x, 0), max(y, 0)
    x1, y1 = min(x + rw, size[0]), min(y + rh, size[1])
    return (x0, y0, x1 - x0, y1 - y0) if x1 > x0 and y1 > y0 else None


def union_rect(a: Rect | None, b: Rect | None) -> Rect | None:
    """The bounding rectangle of two (either may be empty)."""
    if a is None or b is None:
        return a if b is None else b
    x0, y0 = min(a[0], b[0]), min(a[1], b[1])
    x1, y1 = max(a[0] + a[2], b[0] + b[2]), max(a[1] + a[3], b[1] + b[3])
    return (x0, y0, x1 - x0, y1 - y0)


def subtract_rect(a: Rect | None, b: Rect | None) -> list[Rect]:
    """The pixels of `a` outside `b`, as at most four rectangles (the bands below, above,
    left and right of b's part of a)."""
    if a is None:
        return []
    cut = intersect_rect(a, b)
    if cut is None:
        return [a]
    ax0, ay0, ax1, ay1 = a[0], a[1], a[0] + a[2], a[1] + a[3]
    cx0, cy0, cx1, cy1 = cut[0], cut[1], cut[0] + cut[2], cut[1] + cut[3]
    bands = [
        (ax0, ay0, ax1 - ax0, cy0 - ay0),
        (ax0, cy1, ax1 - ax0, ay1 - cy1),
        (ax0, cy0, cx0 - ax0, cy1 - cy0),
        (cx1, cy0, ax1 - cx1, cy1 - cy0),
    ]
    return [band for band in bands if band[2] > 0 and band[3] > 0]


def grow_rect(rect: Rect | None, pixels: int, size: tuple[int, int]) -> Rect | None:
    if rect is None:
        return None
    x, y, w, h = rect
    return clamp_rect((x - pixels, y - pixels, w + 2 * pixels, h + 2 * pixels), size)


def full_rect(size: tuple[int, int]) -> Rect:
    return (0, 0, int(size[0]), int(size[1]))
