"""What the renderer draws: the structure plus the live state (probe, navigation cube,
clipping planes, lights, effect switches), and the CPU culling that picks the atoms
drawn as spheres.

Planes are (a, b, c, d) with a·x + b·y + c·z + d >= 0 kept, normalised so that the
value is a signed distance in Å.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sasprobe.molecule import DEFAULT_PROBE_RADIUS, Structure, UniformGrid
from sasprobe.protocol.scene import DEFAULT_LIGHT_DIRECTION


def normalise_plane(plane) -> np.ndarray:
    """A plane scaled to a unit normal; ValueError for a zero normal or non-finite values."""
    p = np.asarray(plane, dtype=np.float64).reshape(4)
    n = float(np.linalg.norm(p[:3]))
    if not np.all(np.isfinite(p)) or n == 0.0:
        raise ValueError(f"clip plane {tuple(p)} has no direction (a, b, c must not all be 0)")
    return p / n


@dataclass
class Probe:
    center: np.ndarray  # Å, molecule frame
    radius: float = DEFAULT_PROBE_RADIUS
    touched_atom: int = -1


@dataclass
class NavCube:
    center: np.ndarray
    half: float  # half the edge, Å

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.center - self.half, self.center + self.half

    def planes(self) -> np.ndarray:
        """The six faces as planes that keep the inside."""
        c, h = self.center, self.half
        out = []
        for axis in range(3):
            n = np.zeros(3)
            n[axis] = 1.0
            out.append([*n, -(c[axis] - h)])  # x >= c - h
            out.append([*(-n), c[axis] + h])  # x <= c + h
        return np.array(out)


@dataclass(frozen=True)
class Mark:
    """A mark the daemon's scene carries (protocol/README.md `marks`)."""

    id: int
    label: str
    position: tuple[float, float, float]  # Å, molecule frame


@dataclass
class Effects:
    """Switches the window's keys toggle (each effect can be turned off)."""

    fxaa: bool = True
    backbone: bool = True  # the trace outside the navigation cube
    nav_cube: bool = True  # cut the spheres down to the cube (when a cube is set)
    cube_wire: bool = True
    probe: bool = True  # draw the probe sphere
    probe_light: bool = True
    directional_light: bool = True
    highlight: bool = True  # the touched atom
    clip_planes: bool = True
    probe_plane: bool = False  # a plane through the probe centre, facing the camera
    readout: bool = True  # on-screen fps / haptic rate / force (window only)
    marks: bool = True  # the session's numbered marks
    # lighting (render/passes/lighting.py; how each is computed: LightingSettings)
    shadows: bool = False
    soft_shadows: bool = False
    ambient_occlusion: bool = False
    edge_cueing: bool = False
    path_tracing: bool = False


@dataclass
class SceneState:
    structure: Structure
    probe_radius: float = DEFAULT_PROBE_RADIUS
    probe: Probe | None = None
    nav_cube: NavCube | None = None
    clip_planes: list[np.ndarray] = field(default_factory=list)
    marks: list[Mark] = field(default_factory=list)
    light_direction: np.ndarray = field(default_factory=lambda: _unit(DEFAULT_LIGHT_DIRECTION))
    effects: Effects = field(default_factory=Effects)

    def __post_init__(self) -> None:
        self._grid: UniformGrid | None = None
        self._grid_key: tuple | None = None
        self.clip_planes = [normalise_plane(p) for p in self.clip_planes]
        self._selection_key: bytes | None = None
        self._selection = np.empty(0, dtype=np.uint32)
        self._atoms_sphere: tuple[np.ndarray, float] | None = None

    @property
    def grid(self) -> UniformGrid:
        """The grid of the expanded (SAS) spheres at the scene's probe radius: the one the
        daemon feels with and the lighting traces through (the renderer also culls to the
        navigation cube with it). Rebuilt when the structure or the probe radius changes,
        so a renderer following a daemon uses the daemon's radius."""
        key = (id(self.structure), float(self.probe_radius))
        if key != self._grid_key:
            self._grid = UniformGrid(self.structure.positions, self.structure.expanded_radii(self.probe_radius))
            self._grid_key = key
        return self._grid

    # ---------------------------------------------------------------- planes
    def active_cube(self) -> NavCube | None:
        return self.nav_cube if (self.nav_cube is not None and self.effects.nav_cube) else None

    def probe_plane(self, eye: np.ndarray) -> np.ndarray | None:
        """The plane through the probe centre facing the camera (keeps what lies beyond
        the probe), so nothing between the eye and the probe hides it."""
        if self.probe is None or not self.effects.probe_plane:
            return None
        n = self.probe.center - np.asarray(eye, dtype=np.float64)
        if np.linalg.norm(n) == 0.0:
            return None
        n = _unit(n)
        return np.array([*n, -float(n @ self.probe.center)])

    def active_planes(self, eye: np.ndarray) -> np.ndarray:
        """User planes (when on) and the probe plane (when on), N x 4."""
        planes = list(self.clip_planes) if self.effects.clip_planes else []
        pp = self.probe_plane(eye)
        if pp is not None:
            planes.append(pp)
        return np.array(planes, dtype=np.float64).reshape(-1, 4)

    # ------------------------------------------------------------- culling
    def sphere_selection(self, eye: np.ndarray) -> np.ndarray:
        """Sorted uint32 ids of the atoms drawn as spheres (cached while nothing changes)."""
        planes = self.active_planes(eye)
        cube = self.active_cube()
        key = planes.tobytes() + (b"" if cube is None else np.array([*cube.center, cube.half]).tobytes())
        if key != self._selection_key:
            self._selection = select_spheres(self.structure, self.grid, planes, cube)
            self._selection_key = key
        return self._selection

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """Centre and radius holding every atom, the probe and the cube (for fitting and clip range)."""
        if self._atoms_sphere is None:
            s = self.structure
            lo = (s.positions - s.vdw_radii[:, None]).min(axis=0)
            hi = (s.positions + s.vdw_radii[:, None]).max(axis=0)
            center = (lo + hi) / 2.0
            self._atoms_sphere = (center, float(np.sqrt(((s.positions - center) ** 2).sum(axis=1)).max() + s.vdw_radii.max()))
        center, radius = self._atoms_sphere
        if self.probe is not None:
            radius = max(radius, float(np.linalg.norm(self.probe.center - center)) + self.probe.radius)
        if self.nav_cube is not None:
            radius = max(radius, float(np.linalg.norm(self.nav_cube.center - center)) + self.nav_cube.half * np.sqrt(3))
        return center, radius


def select_spheres(structure: Structure, grid: UniformGrid, planes: np.ndarray, cube: NavCube | None) -> np.ndarray:
    """Atoms to draw as spheres: those overlapping the cube (when one is set), minus
    those wholly on the removed side of any plane. The cube goes through the grid
    (cells the box overlaps, then an exact sphere-box test with van der Waals radii;
    the grid's expanded spheres contain them, so no candidate is missed)."""
    if cube is not None:
        lo, hi = cube.bounds()
        cand = grid.candidates_in_box(lo, hi)
        c = structure.positions[cand]
        gap = c - np.clip(c, lo, hi)
        cand = cand[np.einsum("ij,ij->i", gap, gap) <= structure.vdw_radii[cand] ** 2]
    else:
        cand = np.arange(structure.n_atoms)
    if planes.size:
        dist = structure.positions[cand] @ planes[:, :3].T + planes[:, 3]
        cand = cand[np.all(dist >= -structure.vdw_radii[cand, None], axis=1)]
    return cand.astype(np.uint32)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)
