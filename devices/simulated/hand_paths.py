"""The simulated arm's hand paths: where the model hand pulls the stylus, one per script.

A hand path is a target position (device frame, mm) for every simulated time t >= 0; it
loops forever, so a daemon can run on it as long as it likes, and `duration_s` is one
pass. `--device sim:SCRIPT` names one; each is placed on the molecule through the
session's initial workspace mapping (devices/workspace/start.py `initial_mapping`, the
same one the haptic engine starts with), using the expanded spheres (vdW + probe) and the
uniform grid:

- `scan`: a raster over the top of the molecule, pressing `SCAN_PRESS_MM` into the
  surface height under each point, so the stylus slides over bumps and creases;
- `dive`: down into the groove between two surface atoms, hold, rock across the
  groove, and back out;
- `press`: down, steadily, into a thin part (the thinnest top-exposed column of
  solid with free space under it; where there is none, such as compact crambin, the
  highest exposed atom and the bulk under it), far enough that the hand pushes
  harder than a penalty wall can resist;
- `orbit`: spiral in to a horizontal circle around the molecule's middle, rubbing
  along its sides;
- `random`: a seeded smooth wander (a sum of sinusoids) through the cube, in and out
  of the molecule;
- `sweep`: hover over the middle of the cube and sweep the hand along device +x, -x,
  +y and -y in turn (the check that the probe moves on screen as the hand does).

Everything starts hovering in free space above the molecule, so the haptic engine seats
its proxy at once, and comes back to the start the way a hand would, lifting over the
surface rather than through it. The scripts set where the hand goes; how hard it may
push is the hand model's (arm.py: never beyond the device's continuous
rating, as a person does not lean on the arm).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np
from sasprobe.devices.workspace.mapping import WorkspaceMapping
from sasprobe.molecule.grid import UniformGrid
from sasprobe.molecule.probe import DEFAULT_PROBE_RADIUS
from sasprobe.molecule.surface import Surface

SCRIPTS = ("scan", "dive", "press", "orbit", "random", "sweep")

HOVER_MM = 4.0  # above the surface before touching ...
HOVER_MIN_A = 2.0  # ... and never closer than this (a small cube's few Å per 4 mm)
SCAN_PRESS_MM = 1.5
SCAN_SPEED_MM_S = 20.0
DIVE_DEPTH_MM = 8.0
PRESS_DEPTH_MM = 20.0
ORBIT_SPEED_MM_S = 25.0
SWEEP_FRACTION = 0.3  # of the drift-free core's half edge
SWEEP_SPEED_MM_S = 20.0


@dataclass
class HandPath:
    """A looping target path: piecewise linear through (time s, point mm) waypoints."""

    name: str
    times: list[float]
    points: list[tuple[float, float, float]]
    # where it was placed (molecule frame), for tests and reports
    info: dict = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return self.times[-1]

    @property
    def start(self) -> tuple[float, float, float]:
        return self.points[0]

    def target(self, t: float) -> tuple[float, float, float]:
        t = t % self.times[-1] if self.times[-1] > 0 else 0.0
        i = bisect.bisect_right(self.times, t) - 1
        if i >= len(self.times) - 1:
            return self.points[-1]
        t0, t1 = self.times[i], self.times[i + 1]
        a, b = self.points[i], self.points[i + 1]
        w = (t - t0) / (t1 - t0) if t1 > t0 else 0.0
        return a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2])


class _PathBuilder:
    """Waypoints at a speed (mm/s) or with explicit durations; closes the loop at the end."""

    def __init__(self, start):
        self.times = [0.0]
        self.points = [tuple(float(v) for v in start)]

    def move(self, point, speed_mm_s: float | None = None, duration_s: float | None = None) -> None:
        point = tuple(float(v) for v in point)
        if duration_s is None:
            duration_s = math.dist(point, self.points[-1]) / speed_mm_s
        self.times.append(self.times[-1] + max(duration_s, 1e-3))
        self.points.append(point)

    def hold(self, duration_s: float) -> None:
        self.move(self.points[-1], duration_s=duration_s)

    def close(self, name: str, info: dict, return_speed_mm_s: float = 30.0) -> HandPath:
        """Back to the start, and the looping path."""
        self.move(self.points[0], speed_mm_s=return_speed_mm_s)
        return HandPath(name, self.times, self.points, info)


def place_hand_path(
    name: str,
    structure,
    mapping: WorkspaceMapping,
    probe_radius: float = DEFAULT_PROBE_RADIUS,
    seed: int = 0,
    surface: Surface | None = None,
) -> HandPath:
    """The hand path of script `name` placed on `structure` through `mapping` (its initial
    state); `surface`:
    the structure's Surface at this probe radius, when the caller has one."""
    if name not in SCRIPTS:
        raise ValueError(f"unknown simulated-arm script {name!r} (known: {', '.join(SCRIPTS)})")
    placer = _Placer(surface or Surface.of(structure, probe_radius), mapping)
    return placer.random(seed) if name == "random" else getattr(placer, name)()


class _Placer:
    def __init__(self, surface: Surface, mapping: WorkspaceMapping):
        self.surface = surface
        self.mapping = mapping.copy()
        self.s = mapping.scale_A_per_mm
        self.center = mapping.cube_center_A
        self.core = mapping.core_half_mm - 0.5  # stay clear of the drift margin
        self.hover = max(HOVER_MM * self.s, HOVER_MIN_A)  # Å
        self.wc = np.asarray(mapping.workspace_center_mm)

    # --------------------------------------------------------------- helpers
    def dev(self, p_A) -> tuple[float, float, float]:
        """Molecule point -> device point, kept inside the drift-free core."""
        d = np.asarray(self.mapping.to_device(*p_A))
        return tuple(float(v) for v in np.clip(d, self.wc - self.core, self.wc + self.core))  # type: ignore[return-value]

    def region(self, fraction: float) -> float:
        return fraction * self.mapping.cube_half_A

    def top_or_floor(self, x: float, y: float) -> float:
        top = self.surface.top(x, y)
        return top if top is not None else self.center[2] - self.region(0.5)

    def exposed_columns(self, limit: int = 400, fraction: float = 0.45) -> list[tuple[int, list]]:
        """Atoms within `fraction` of the cube's half edge of its axis whose top point is the
        top of their column."""
        grid = self.surface.grid
        c = grid.centers
        w = self.region(fraction)
        near = np.flatnonzero(
            (np.abs(c[:, 0] - self.center[0]) <= w) & (np.abs(c[:, 1] - self.center[1]) <= w)
        )
        if near.size == 0:
            near = np.arange(c.shape[0])
        order = near[np.argsort(-(c[near, 2] + grid.radii[near]), kind="stable")][:limit]
        out = []
        for i in order:
            cols = self.surface.intervals(float(c[i, 0]), float(c[i, 1]))
            if cols and i in cols[0][2] and abs(cols[0][1] - (c[i, 2] + grid.radii[i])) < 1e-9:
                out.append((int(i), cols))
        return out

    # --------------------------------------------------------------- the scripts
    def scan(self) -> HandPath:
        w = self.region(0.4)
        cx, cy = self.center[0], self.center[1]
        press = SCAN_PRESS_MM * self.s
        lines = 5
        step = 0.5
        xs = np.arange(-w, w + 1e-9, step)
        waypoints = []
        for k, y in enumerate(np.linspace(-w, w, lines)):
            for x in xs if k % 2 == 0 else xs[::-1]:
                waypoints.append((cx + x, cy + y, self.top_or_floor(cx + x, cy + y) - press))
        first = waypoints[0]
        hover = self.dev((first[0], first[1], first[2] + press + self.hover))
        path = _PathBuilder(hover)
        for p in waypoints:
            path.move(self.dev(p), speed_mm_s=SCAN_SPEED_MM_S)
        last = waypoints[-1]
        clear = max(p[2] for p in waypoints) + press + self.hover  # above every point of the region
        path.move(self.dev((last[0], last[1], clear)), speed_mm_s=SCAN_SPEED_MM_S)
        path.move(self.dev((first[0], first[1], clear)), speed_mm_s=SCAN_SPEED_MM_S)
        return path.close("scan", {"region_half_A": w, "lines": lines, "press_mm": SCAN_PRESS_MM})

    def dive(self) -> HandPath:
        best = None
        for fraction in (0.45, 0.8):  # a small cube may have no groove near its axis: look wider
            best = self._groove(fraction)
            if best is not None:
                break
        if best is None:
            raise ValueError("no groove between two top-exposed atoms found for the dive script")
        grid = self.surface.grid
        _, i, j, crease = best
        across = grid.centers[j] - grid.centers[i]
        across[2] = 0.0
        across = across / (np.linalg.norm(across) or 1.0)
        hover = self.dev(crease + np.array([0, 0, self.hover]))
        bottom = crease - np.array([0, 0, DIVE_DEPTH_MM * self.s])
        rock = across * 1.5 * self.s
        path = _PathBuilder(hover)
        path.hold(0.3)
        path.move(self.dev(crease + np.array([0, 0, 0.5 * self.s])), duration_s=0.5)
        path.move(self.dev(bottom), duration_s=1.0)
        path.hold(0.5)
        for _ in range(2):
            path.move(self.dev(bottom + rock), duration_s=0.4)
            path.move(self.dev(bottom - rock), duration_s=0.8)
            path.move(self.dev(bottom), duration_s=0.4)
        path.move(hover, duration_s=0.6)
        info = {
            "atoms": (i, j),
            "crease_A": [float(v) for v in crease],
            "push_direction": (0.0, 0.0, -1.0),
        }
        return path.close("dive", info)

    def _groove(self, fraction: float):
        """(depth, i, j, crease) of the deepest uncovered crease between two top-exposed atoms."""
        grid = self.surface.grid
        exposed = self.exposed_columns(fraction=fraction)
        best = None
        tops = {i: cols[0][1] for i, cols in exposed}
        ids = np.array(sorted(tops), dtype=np.int64)
        c, r = grid.centers[ids], grid.radii[ids]
        dist = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=2)
        overlapping = (dist < r[:, None] + r[None, :]) & (dist > np.abs(r[:, None] - r[None, :]))
        for a, b in zip(*np.nonzero(np.triu(overlapping, 1))):
            i, j = int(ids[a]), int(ids[b])
            crease = _circle_top(grid, i, j)
            if crease is None:
                continue
            top = self.surface.top(crease[0], crease[1])
            if top is None or abs(top - crease[2]) > 1e-6:
                continue  # the crease is covered by something above it
            depth = min(tops[i], tops[j]) - crease[2]
            if best is None or depth > best[0]:
                best = (depth, i, j, crease)
        return best

    def press(self) -> HandPath:
        grid = self.surface.grid
        best = None
        fallback = None
        for i, cols in self.exposed_columns():
            top_lo, top_hi, _ = cols[0]
            gap = (top_lo - cols[1][1]) if len(cols) > 1 else math.inf
            thickness = top_hi - top_lo
            if fallback is None:
                fallback = (thickness, i, top_hi, top_lo, gap)
            if gap >= 2.0 and thickness <= 2.0 * float(grid.radii[i]) + 1.5:
                if best is None or thickness < best[0]:
                    best = (thickness, i, top_hi, top_lo, gap)
        chosen = best or fallback
        if chosen is None:
            raise ValueError("no top-exposed atom found for the press script")
        thickness, i, top_hi, top_lo, gap = chosen
        x, y = float(grid.centers[i, 0]), float(grid.centers[i, 1])
        surface = np.array([x, y, top_hi])
        hover = self.dev(surface + np.array([0, 0, self.hover]))
        path = _PathBuilder(hover)
        path.hold(0.3)
        path.move(self.dev(surface + np.array([0, 0, 0.5 * self.s])), duration_s=0.5)
        path.move(self.dev(surface - np.array([0, 0, PRESS_DEPTH_MM * self.s])), duration_s=1.5)
        path.hold(1.0)
        path.move(hover, duration_s=1.0)
        info = {
            "atom": i,
            "surface_A": [float(v) for v in surface],
            "thickness_A": thickness,
            "far_side_z_A": top_lo,
            "gap_below_A": gap,
            "thin": best is not None,
            "push_direction": (0.0, 0.0, -1.0),
        }
        return path.close("press", info)

    def orbit(self) -> HandPath:
        cx, cy, cz = (float(v) for v in self.center)
        # The cube's middle height, or higher where the molecule fills the cube there (a
        # zoomed-in cube on a surface): the lowest height with free space to start from.
        for z in np.arange(cz, cz + self.region(0.8), 0.5):
            extents = np.array(
                [
                    self._radial_extent(cx, cy, float(z), math.cos(a), math.sin(a))
                    for a in np.linspace(0, 2 * math.pi, 36, endpoint=False)
                ]
            )
            if extents.max() + self.hover <= self.region(0.8):
                break
        cz = float(z)
        reach = float(extents.max()) if extents.max() > 0 else self.region(0.5)
        radius = 0.85 * float(np.median(extents)) if np.median(extents) > 0 else 0.5 * reach
        outside = min(reach + self.hover, self.region(0.8))
        path = _PathBuilder(self.dev((cx + outside, cy, cz)))
        path.hold(0.3)
        steps = 72
        turn_s = 2 * math.pi * radius / self.s / ORBIT_SPEED_MM_S
        for k in range(1, steps + 1):  # spiral in over a quarter turn, then one full turn
            a = 2 * math.pi * k / steps
            r = radius + (outside - radius) * max(0.0, 1.0 - 4.0 * k / steps)
            path.move(
                self.dev((cx + r * math.cos(a), cy + r * math.sin(a), cz)),
                duration_s=turn_s / steps,
            )
        info = {"radius_A": radius, "height_A": cz}
        return path.close("orbit", info)

    def _radial_extent(self, cx, cy, cz, ux, uy) -> float:
        """Farthest distance from the axis along a horizontal ray where the ray is in the SAS."""
        grid = self.surface.grid
        far = 0.0
        for r in np.arange(0.0, self.region(1.0), 0.5):
            p = (cx + r * ux, cy + r * uy, cz)
            if grid.spheres_within(p, 0.0).size:
                far = float(r)
        return far

    def random(self, seed: int) -> HandPath:
        rng = np.random.default_rng(seed)
        core = self.core
        # A sum of three sinusoids per axis: smooth, endless, reproducible from the seed.
        freqs = rng.uniform(0.05, 0.35, size=(3, 3))
        phases = rng.uniform(0, 2 * math.pi, size=(3, 3))
        amps = rng.uniform(0.2, 0.33, size=(3, 3)) * core
        duration = 30.0
        top = self.top_or_floor(float(self.center[0]), float(self.center[1]))
        hover = np.asarray(self.dev((self.center[0], self.center[1], top + self.hover)))
        path = _PathBuilder(hover)
        for t in np.arange(0.02, duration, 0.02):
            wander = self.wc + (amps * np.sin(2 * math.pi * freqs * t + phases)).sum(axis=1)
            blend = min(1.0, t / 1.5)  # leave the hover point gently
            path.move(
                np.clip(hover + blend * (wander - hover), self.wc - core, self.wc + core),
                duration_s=0.02,
            )
        return path.close("random", {"seed": seed})

    def sweep(self) -> HandPath:
        top = self.top_or_floor(float(self.center[0]), float(self.center[1]))
        hover = np.asarray(self.dev((self.center[0], self.center[1], top + self.hover)))
        reach = SWEEP_FRACTION * self.core
        path = _PathBuilder(hover)
        path.hold(0.3)
        for axis, sign in ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)):
            end = hover.copy()
            end[axis] += sign * reach
            path.move(end, speed_mm_s=SWEEP_SPEED_MM_S)
            path.hold(0.2)
            path.move(hover, speed_mm_s=SWEEP_SPEED_MM_S)
        return path.close("sweep", {"reach_mm": reach, "hover_mm": [float(v) for v in hover]})


def _circle_top(grid: UniformGrid, i: int, j: int):
    """Highest point of the circle where spheres i and j meet, or None when they do not."""
    ci, cj = grid.centers[i], grid.centers[j]
    ri, rj = float(grid.radii[i]), float(grid.radii[j])
    axis = cj - ci
    dist = float(np.linalg.norm(axis))
    if dist == 0 or dist >= ri + rj or dist <= abs(ri - rj):
        return None
    axis = axis / dist
    along = (dist * dist + ri * ri - rj * rj) / (2 * dist)
    rho = math.sqrt(max(ri * ri - along * along, 0.0))
    up = np.array([0.0, 0.0, 1.0]) - axis[2] * axis
    if np.linalg.norm(up) < 1e-9:
        return None
    return ci + along * axis + rho * up / np.linalg.norm(up)
