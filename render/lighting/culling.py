"""What the clip planes and the navigation cube remove, as the lighting sees it: which atoms
keep nothing (culled: the GPU skips them), which have their centre cut away (analytic AO
skips them), and the cuts a shadow ray to a point light can cross."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sasprobe.molecule.grid import UniformGrid
from sasprobe.render.gl.uniforms import MAX_CLIP_PLANES, padded_planes

# Å: a point light this far inside a cut leaves its shadow rays whole (Culling.cuts_before).
LIGHT_CUT_MARGIN = 0.01


@dataclass
class Culling:
    """Clip planes (kept where a·x + b·y + c·z + d >= 0) and the navigation cube.

    What is drawn, and what casts shadows and occludes, is every sphere intersected with
    the kept half-spaces and the cube (atoms crossing a face are cut, their caps drawn).
    Atoms that keep nothing are *culled*: flagged so that the GPU skips them outright.
    """

    clip_planes: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    nav_cube: tuple[np.ndarray, float] | None = None  # centre (Å), half edge (Å)
    # Uniforms, cuts
    _found: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        planes = np.asarray(self.clip_planes, dtype=np.float64).reshape(-1, 4)
        if planes.shape[0] > MAX_CLIP_PLANES:
            raise ValueError(
                f"at most {MAX_CLIP_PLANES} clip planes are supported, got {planes.shape[0]}"
            )
        norms = np.linalg.norm(planes[:, :3], axis=1)
        if np.any(norms == 0):
            raise ValueError("a clip plane needs a non-zero normal")
        self.clip_planes = planes / norms[:, None]  # unit normals: d is then a distance in Å
        if self.nav_cube is not None:
            centre, half = self.nav_cube
            self.nav_cube = (np.asarray(centre, dtype=np.float64).reshape(3), float(half))

    @property
    def clipping(self) -> bool:
        """Whether anything is cut away (shaders compiled with NO_CLIPPING assume not)."""
        return self.clip_planes.shape[0] > 0 or self.nav_cube is not None

    @property
    def cube_box(self) -> tuple[np.ndarray, np.ndarray] | None:
        if self.nav_cube is None:
            return None
        centre, half = self.nav_cube
        return centre - half, centre + half

    def all_planes(self) -> np.ndarray:
        """The clip planes and the cube's faces, as planes (N x 4, unit normals)."""
        if "planes" not in self._found:
            planes, box = self.clip_planes, self.cube_box
            if box is not None:  # kept where n·x + d >= 0
                planes = np.concatenate(
                    [
                        planes,
                        np.column_stack([np.eye(3), -box[0]]),
                        np.column_stack([-np.eye(3), box[1]]),
                    ]
                )
            self._found["planes"] = planes
        return self._found["planes"]

    def cuts_before(self, light) -> Culling:
        """The cuts a shadow ray from a kept point to a point light at `light` can cross: the
        planes (the cube's faces among them) the light does not lie LIGHT_CUT_MARGIN Å
        inside of. A segment between two points a half-space keeps lies in it (it is
        convex), so the others leave the ray whole; the margin holds the float32 test of
        the light's end in the shaders. The cube's faces come as planes, and the whole
        culling when they do not fit the shaders' arrays."""
        planes = self.all_planes()
        crossed = (
            planes[:, :3] @ np.asarray(light, dtype=np.float64).reshape(3) + planes[:, 3]
            < LIGHT_CUT_MARGIN
        )
        if np.count_nonzero(crossed) > MAX_CLIP_PLANES:
            return self
        key = ("cuts", crossed.tobytes())
        if key not in self._found:  # the same few cuts frame after frame
            self._found[key] = Culling(planes[crossed], None)
        return self._found[key]

    def culled_atoms(
        self, centers: np.ndarray, radii: np.ndarray, grid: UniformGrid | None = None
    ) -> np.ndarray:
        """Boolean mask of atoms of which nothing is kept (wholly behind a plane, or not
        overlapping the cube). `grid` speeds up the cube test through its box → cells query."""
        centers = np.asarray(centers, dtype=np.float64)
        radii = np.asarray(radii, dtype=np.float64)
        culled = np.zeros(centers.shape[0], dtype=bool)
        for a, b, c, d in self.clip_planes:
            culled |= centers @ np.array([a, b, c]) + d < -radii
        box = self.cube_box
        if box is not None:
            lo, hi = box
            if grid is not None:
                candidates = grid.candidates_in_box(lo, hi)  # superset: grid radii >= vdW
            else:
                candidates = np.arange(centers.shape[0])
            nearest = np.clip(centers[candidates], lo, hi)
            gap = centers[candidates] - nearest
            overlapping = np.zeros(centers.shape[0], dtype=bool)
            overlapping[candidates[np.einsum("ij,ij->i", gap, gap) <= radii[candidates] ** 2]] = (
                True
            )
            culled |= ~overlapping
        return culled

    def centre_clipped(self, centers: np.ndarray) -> np.ndarray:
        """Boolean mask of atoms whose centre lies in a removed half-space or outside the cube.

        Analytic AO treats a neighbour as a whole sphere; one whose centre is cut away
        keeps at most a cap under the cut, and counting it whole would black out the caps
        drawn on the cut (their points lie inside such neighbours), so it is skipped."""
        centers = np.asarray(centers, dtype=np.float64)
        clipped = np.zeros(centers.shape[0], dtype=bool)
        for a, b, c, d in self.clip_planes:
            clipped |= centers @ np.array([a, b, c]) + d < 0
        box = self.cube_box
        if box is not None:
            clipped |= np.any((centers < box[0]) | (centers > box[1]), axis=1)
        return clipped

    def uniforms(self) -> dict[str, object]:
        if "uniforms" not in self._found:
            box = self.cube_box
            lo, hi = box if box is not None else (np.zeros(3), np.zeros(3))
            self._found["uniforms"] = {
                "u_clip_count": int(self.clip_planes.shape[0]),
                "u_clip_planes": padded_planes(self.clip_planes).tobytes(),
                "u_cube_on": int(box is not None),
                "u_cube_lo": tuple(float(v) for v in lo),
                "u_cube_hi": tuple(float(v) for v in hi),
            }
        return self._found["uniforms"]


def cube_culling(planes: np.ndarray, cube) -> Culling:
    """The lighting's culling for a frame's planes and navigation cube (a NavCube or None):
    an axis-aligned cube as the grid's box (its walk range shrinks to the cube), a turned
    one as its six face planes."""
    if cube is None:
        return Culling(planes, None)
    if cube.axis_aligned:
        return Culling(planes, (cube.center, cube.half))
    return Culling(np.concatenate([planes.reshape(-1, 4), cube.planes()]), None)
