"""What the renderer draws: the structure plus the live state (probe, navigation cube,
clipping planes, lights, colour scheme, effect switches), and the CPU culling that picks
the atoms drawn as spheres.

Planes are (a, b, c, d) with a·x + b·y + c·z + d >= 0 kept, normalised so that the
value is a signed distance in Å. The navigation cube turns with the workspace view: its
axes are the device's axes in the molecule frame (identity until the view is turned).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, Structure, UniformGrid
from sasprobe.molecule.colors import AtomAreas, default_scheme
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
    # Where the device tip maps (Å); differs from `center` in contact.
    goal: np.ndarray | None = None
    force_n: np.ndarray | None = None  # the force on the hand, N, in the molecule frame
    tip_mm: np.ndarray | None = None  # the device tip, mm, device frame (what the hand does)


@dataclass
class NavCube:
    center: np.ndarray
    half: float  # half the edge, Å
    # Columns: the cube's x, y, z (device axes)
    axes: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        self.axes = np.asarray(self.axes, dtype=np.float64).reshape(3, 3)

    @property
    def axis_aligned(self) -> bool:
        """Whether the cube's faces are the molecule frame's planes (no turn, or quarter turns)."""
        a = np.abs(self.axes)
        return bool(np.all((a < 1e-12) | (np.abs(a - 1.0) < 1e-12)))

    def key(self) -> bytes:
        """Bytes that change whenever the cube does (for caches)."""
        return np.array([*self.center, self.half, *self.axes.ravel()]).tobytes()

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The axis-aligned box holding the cube."""
        reach = self.half * np.abs(self.axes).sum(axis=1)
        return self.center - reach, self.center + reach

    def local(self, points) -> np.ndarray:
        """Points in the cube's own frame (relative to its centre, along its axes)."""
        return (np.asarray(points, dtype=np.float64) - self.center) @ self.axes

    def corners(self) -> np.ndarray:
        """(8, 3) corners, molecule frame."""
        signs = np.array(
            [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64
        )
        return self.center + self.half * signs @ self.axes.T

    def planes(self) -> np.ndarray:
        """The six faces as planes that keep the inside."""
        c, h = self.center, self.half
        out = []
        for axis in range(3):
            n = self.axes[:, axis]
            out.append([*n, -(float(n @ c) - h)])  # n·x >= n·c - h
            out.append([*(-n), float(n @ c) + h])  # n·x <= n·c + h
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
    probe_plane: bool = False  # a plane at the probe, facing the camera (SceneState.probe_plane)
    readout: bool = True  # on-screen fps / haptic rate / force (window only)
    marks: bool = True  # the session's numbered marks
    # lighting (render/passes/lighting.py; how each is computed: LightingSettings)
    shadows: bool = False
    soft_shadows: bool = False
    ambient_occlusion: bool = False
    edge_cueing: bool = False
    path_tracing: bool = False
    # protocol/scene.py COLOR_SCHEMES; None: the default by structure (C key)
    color_scheme: str | None = None


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
    force_ratings_n: tuple[float, float] | None = None  # the device's (continuous, peak) force, N
    # True: light_direction is in the camera's frame (x right, y up, z towards the viewer) and
    # the light turns with the camera; False: it is fixed in the molecule frame.
    lights_follow_camera: bool = False

    def __post_init__(self) -> None:
        self._grid: UniformGrid | None = None
        self._grid_key: tuple | None = None
        self.clip_planes = [normalise_plane(p) for p in self.clip_planes]
        self._selection_key: bytes | None = None
        self._selection = np.empty(0, dtype=np.uint32)
        self._atoms_sphere: tuple[np.ndarray, float] | None = None
        self.atom_areas = AtomAreas()  # per-atom SAS of self.grid, for the sas colours
        self._default_scheme: str | None = None

    @property
    def grid(self) -> UniformGrid:
        """The grid of the expanded (SAS) spheres at the scene's probe radius: the one the
        daemon feels with and the lighting traces through (the renderer also culls to the
        navigation cube with it). Rebuilt when the structure or the probe radius changes,
        so a renderer following a daemon uses the daemon's radius."""
        key = (id(self.structure), float(self.probe_radius))
        if key != self._grid_key:
            self._grid = UniformGrid(
                self.structure.positions, self.structure.expanded_radii(self.probe_radius)
            )
            self._grid_key = key
        return self._grid

    def color_scheme(self) -> str:
        """The scheme in effect: the one chosen, else the structure's default."""
        if self.effects.color_scheme is not None:
            return self.effects.color_scheme
        if self._default_scheme is None:
            self._default_scheme = default_scheme(self.structure)
        return self._default_scheme

    def world_light_direction(self, camera) -> np.ndarray:
        """The direction the directional light travels, in the molecule frame, for this camera."""
        if not self.lights_follow_camera:
            return self.light_direction
        return camera.basis() @ self.light_direction

    # ---------------------------------------------------------------- planes
    def active_cube(self) -> NavCube | None:
        return self.nav_cube if (self.nav_cube is not None and self.effects.nav_cube) else None

    def probe_plane(self, camera) -> np.ndarray | None:
        """The plane facing the camera (square to its view axis) that keeps what lies beyond
        the probe, so nothing between the eye and the probe hides it. Its depth steps by the
        probe's radius: the plane sits at most that far behind the probe centre, inside the
        probe's back half, which covers what it cuts there; and it stands still while the
        probe moves within one step, so the molecule layer, which it cuts, can be kept across
        those frames (render/frame_planner.py)."""
        if self.probe is None or not self.effects.probe_plane:
            return None
        n = np.asarray(camera.target, dtype=np.float64) - np.asarray(camera.eye, dtype=np.float64)
        if np.linalg.norm(n) == 0.0:
            return None
        n = _unit(n)
        step = self.probe.radius
        depth = float(np.ceil(float(n @ self.probe.center) / step)) * step
        return np.array([*n, -depth])

    def active_planes(self, camera, probe_plane: bool = True) -> np.ndarray:
        """User planes (when on) and the probe plane (when on, unless not `probe_plane`), N x 4."""
        planes = list(self.clip_planes) if self.effects.clip_planes else []
        pp = self.probe_plane(camera) if probe_plane else None
        if pp is not None:
            planes.append(pp)
        return np.array(planes, dtype=np.float64).reshape(-1, 4)

    # ------------------------------------------------------------- culling
    def sphere_selection(self, camera) -> np.ndarray:
        """Sorted uint32 ids of the atoms drawn as spheres (cached while nothing changes)."""
        planes = self.active_planes(camera)
        cube = self.active_cube()
        key = planes.tobytes() + (b"" if cube is None else cube.key())
        if key != self._selection_key:
            self._selection = select_spheres(self.structure, self.grid, planes, cube)
            self._selection_key = key
        return self._selection

    def framing_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """(centres, radii) the whole-molecule view frames: every atom, whatever the probe
        and the cube do (the navigation cube, often larger than the molecule, is the
        workspace view's to frame)."""
        return self.structure.positions, self.structure.vdw_radii

    def bounding_sphere(self, with_probe: bool = True) -> tuple[np.ndarray, float]:
        """Centre and radius holding every atom, the probe (unless not `with_probe`) and the cube
        (for fitting and clip range)."""
        if self._atoms_sphere is None:
            s = self.structure
            lo = (s.positions - s.vdw_radii[:, None]).min(axis=0)
            hi = (s.positions + s.vdw_radii[:, None]).max(axis=0)
            center = (lo + hi) / 2.0
            self._atoms_sphere = (
                center,
                float(np.sqrt(((s.positions - center) ** 2).sum(axis=1)).max() + s.vdw_radii.max()),
            )
        center, radius = self._atoms_sphere
        if self.probe is not None and with_probe:
            radius = max(
                radius, float(np.linalg.norm(self.probe.center - center)) + self.probe.radius
            )
        if self.nav_cube is not None:
            radius = max(
                radius,
                float(np.linalg.norm(self.nav_cube.center - center))
                + self.nav_cube.half * np.sqrt(3),
            )
        return center, radius


def select_spheres(
    structure: Structure, grid: UniformGrid, planes: np.ndarray, cube: NavCube | None
) -> np.ndarray:
    """Atoms to draw as spheres: those overlapping the cube (when one is set), minus
    those wholly on the removed side of any plane. The cube goes through the grid
    (cells the box overlaps, then an exact sphere-box test with van der Waals radii;
    the grid's expanded spheres contain them, so no candidate is missed)."""
    if cube is not None:
        lo, hi = cube.bounds()
        cand = grid.candidates_in_box(lo, hi)
        q = cube.local(structure.positions[cand])  # an exact sphere-box test in the cube's frame
        gap = q - np.clip(q, -cube.half, cube.half)
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
