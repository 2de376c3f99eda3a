"""The molecule layer kept across frames: its key, and the screen rectangles the probe
touches.

A frame is two layers. The *molecule layer* is the G-buffer of the atoms and the
backbone trace, with every lighting term that does not depend on the probe (the
molecule's own shadows of the directional light, its ambient occlusion). It depends on
everything the renderer knows except the probe, so its key is built from all of that:
the scene field by field with only `probe` left out, the camera, the frame size, the
planes and cube in effect, and every pass's `state()` (its settings). A field another
part of the program adds to the scene, a camera or a pass's settings dataclass is in
the key without being listed anywhere. While the key holds, a frame restores the
rectangle the probe covered from a copy of the molecule layer (render/gl/gbuffer_stash.py),
draws the probe again and recomputes only what the probe changes.

Rectangles are (x, y, width, height) in pixels with y up (GL's window and image
coordinates), clamped to the frame; None is an empty one.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from sasprobe.molecule import Structure
from sasprobe.render.gl.gbuffer_stash import GBufferStash

Rect = tuple[int, int, int, int]


def state_key(value, skip: tuple[str, ...] = ()):
    """A comparable snapshot of plain state. Dataclasses go field by field (the names in
    `skip` are left out at the top level only), numpy arrays by dtype, shape and bytes,
    containers element by element. A Structure counts by identity: structures are never
    changed in place (a new one is loaded). Anything else counts by its type and identity,
    so replacing it changes the key."""
    if value is None or isinstance(value, (bool, int, float, str, bytes)):
        return value
    if isinstance(value, Structure):
        return ("Structure", id(value))
    if isinstance(value, np.ndarray):
        return ("array", value.dtype.str, value.shape, value.tobytes())
    if isinstance(value, np.generic):
        return value.item()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return (type(value).__name__,) + tuple(
            (f.name, state_key(getattr(value, f.name))) for f in dataclasses.fields(value) if f.name not in skip)
    if isinstance(value, (list, tuple)):
        return tuple(state_key(v) for v in value)
    if isinstance(value, dict):
        return tuple(sorted((str(k), state_key(v)) for k, v in value.items()))
    return (type(value).__name__, id(value))


def molecule_key(frame, passes) -> tuple:
    """The molecule layer's key of a frame: all it is drawn from, the probe excepted."""
    return (
        state_key(frame.scene, skip=("probe",)),
        state_key(frame.camera),
        tuple(frame.size),
        state_key(frame.view), state_key(frame.proj), state_key(frame.planes), state_key(frame.cube),
        state_key(frame.light_direction), frame.buffers.color_version,
        tuple((type(p).__name__, state_key(p.state())) for p in passes),
    )


# ------------------------------------------------------------------ rectangles
def sphere_rect(center, radius: float, viewproj: np.ndarray, size: tuple[int, int], margin: int = 2) -> Rect | None:
    """Pixels a sphere can cover: the bounding box of its enclosing cube's eight corners
    projected (the cube holds the sphere, so its image holds the sphere's), grown by
    `margin`. The whole frame when a corner lies behind the eye; None when off screen."""
    return points_rect(_cube_corners(center, radius), viewproj, size, margin)


def capsule_rect(a, b, radius: float, viewproj: np.ndarray, size: tuple[int, int], margin: int = 2) -> Rect | None:
    """Pixels a capsule (the segment a-b swept by a sphere) can cover: the bounding box of
    the corners of both end spheres' cubes projected (the capsule lies in their convex
    hull, and so does its image), grown by `margin`; as sphere_rect otherwise."""
    return points_rect(np.vstack([_cube_corners(a, radius), _cube_corners(b, radius)]), viewproj, size, margin)


def _cube_corners(center, radius: float) -> np.ndarray:
    return np.array(np.meshgrid(*[[c - radius, c + radius] for c in np.asarray(center, dtype=np.float64)],
                                indexing="ij")).reshape(3, -1).T


def points_rect(points: np.ndarray, viewproj: np.ndarray, size: tuple[int, int], margin: int) -> Rect | None:
    """The bounding box of points (N x 3, world) projected, grown by `margin`; the whole
    frame when one lies behind the eye, None when the box is off screen."""
    clip = np.column_stack([points, np.ones(len(points))]) @ np.asarray(viewproj, dtype=np.float64).T
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


def atoms_rect(positions: np.ndarray, radius: float, viewproj: np.ndarray, size: tuple[int, int]) -> Rect | None:
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
    bands = [(ax0, ay0, ax1 - ax0, cy0 - ay0), (ax0, cy1, ax1 - ax0, ay1 - cy1),
             (ax0, cy0, cx0 - ax0, cy1 - cy0), (cx1, cy0, ax1 - cx1, cy1 - cy0)]
    return [band for band in bands if band[2] > 0 and band[3] > 0]


def grow_rect(rect: Rect | None, pixels: int, size: tuple[int, int]) -> Rect | None:
    if rect is None:
        return None
    x, y, w, h = rect
    return clamp_rect((x - pixels, y - pixels, w + 2 * pixels, h + 2 * pixels), size)


def full_rect(size: tuple[int, int]) -> Rect:
    return (0, 0, int(size[0]), int(size[1]))


class MoleculeCache:
    """The renderer's molecule layer across frames: whether the last frame's still holds
    (`begin`), and the stash of what lies under the probe (`save_under`)."""

    def __init__(self, ctx, programs):
        self.ctx = ctx
        self.programs = programs
        self.stash: GBufferStash | None = None
        self.key: tuple | None = None  # the kept layer's key (None: none kept)
        self.last_key: tuple | None = None  # the last frame's key, layer kept or not
        self.last_held = False  # whether the last frame used the kept layer
        self.stashed: Rect | None = None  # what the stash holds: the probe's rectangle of the last frame
        self.layer_rect: tuple | None = None  # (the pixels the molecule layer can cover,): Frame.molecule_rect, per key
        self.hits = self.misses = self.plain = 0  # plain: misses drawn whole, no layer kept

    def begin(self, frame, passes) -> bool | None:
        """True when the molecule layer kept from the last frame is this frame's too; its
        G-buffer then gets back what the probe covered. False: the layer is drawn anew and
        kept. None: the frame is drawn whole, as without the cache, and nothing is kept —
        the last frame missed too and this one's key differs from its (the camera turning,
        the cube drifting): a layer kept now would most likely not be used, and drawing the
        layer apart from the probe costs more than a whole frame. The layer is drawn again
        once the key holds for a frame."""
        key = molecule_key(frame, passes)
        held = key == self.key
        last, last_held = self.last_key, self.last_held
        self.last_key, self.last_held = key, held
        if held and self.stashed is not None:
            self.stash.restore(frame.targets, self.stashed)
        self.stashed = None
        if held:
            self.hits += 1
            return True
        self.misses += 1
        self.layer_rect = None  # the layer's rectangle is found again when asked for
        if not last_held and last is not None and key != last:
            self.key = None
            self.plain += 1
            return None
        self.key = key
        return False

    def save_under(self, frame, rect: Rect | None) -> None:
        """Keep the molecule layer's pixels of `rect` (about to be drawn over by the probe)."""
        if self.stash is None or self.stash.size != tuple(frame.size):
            if self.stash is not None:
                self.stash.release()
            self.stash = GBufferStash(self.ctx, self.programs, frame.size)
        self.stash.save(frame.targets, rect)
        self.stashed = rect

    def release(self) -> None:
        if self.stash is not None:
            self.stash.release()
            self.stash = None
