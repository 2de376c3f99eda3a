"""The haptic engine the daemon loop calls once per control tick.

    engine = HapticEngine(structure, device.info.limits, HapticSettings())
    out = engine.step(device.read())        # force in the device frame, proxy, ...
    device.write_force(out.force_n)

One tick: device tip (mm) -> workspace drift -> goal in the molecule frame (Å) ->
contact (the god-object proxy, or the penalty baseline) -> spring-damper force in the
device frame, clamped to the device's maximum. `step` is deterministic: it reads no
clock (dt comes from `state.t_ns` differences) and uses only ordered, plain float
arithmetic, so replaying the same DeviceStates gives bit-identical outputs.

Safety:
- non-finite position/velocity or a bad timestamp: zero force, `fault=True`; the proxy
  keeps its place, so a short glitch never lets the probe pass through the surface;
- `calibrated=False`: zero force and the proxy is unseated (see below);
- force never exceeds `limits.max_force_n` (`clamped=True` when it would), never NaN.

Seating: the proxy needs a valid start. At construction, after `reset()`,
`set_structure()`, a method change, or a probe-radius change that puts it inside the
new SAS, the proxy is *unseated*: the output force is zero and `proxy_A` follows the
goal until the goal is in free space; the proxy is seated there and contact works as
usual from then on. So a reconnect with the tip inside the molecule never kicks the
user's hand; they feel nothing until they back out, then the surface again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np
from sasprobe.daemon.haptics.force_law import ZERO, contact_force
from sasprobe.daemon.haptics.neighbours import NeighbourCache
from sasprobe.daemon.haptics.penalty import penalty_contact
from sasprobe.daemon.haptics.proxy import ProxySolver
from sasprobe.daemon.haptics.settings import HapticSettings
from sasprobe.devices.base import DeviceLimits, DeviceState
from sasprobe.devices.workspace.mapping import WorkspaceMapping
from sasprobe.devices.workspace.start import initial_half, initial_mapping
from sasprobe.molecule.grid import UniformGrid
from sasprobe.molecule.structure import Structure
from sasprobe.molecule.surface import Surface

MAX_DT_S = 0.05  # a longer gap between ticks (a stall) drifts the cube by at most this much time
# The proxy may travel, per tick, twice the goal's own motion plus SNAP_SPEED_MM_S * dt
# (device-frame equivalent). Following the goal is never limited, but a snap between
# local minima deep inside a crevice (Å in one tick) is spread over several ticks:
# the force then changes by at most about K * 0.3 mm per 1 ms tick.
SNAP_SPEED_MM_S = 300.0
MIN_SNAP_DT_S = 1e-3  # the budget of a tick with no time step (first tick, equal stamps)


def _xyz(value) -> tuple[float, float, float]:
    """Three floats from a (3,) array or sequence (ValueError/TypeError otherwise)."""
    if type(value) is np.ndarray and value.shape == (3,):
        value = value.tolist()  # far cheaper than iterating numpy scalars
    x, y, z = value
    return float(x), float(y), float(z)


@dataclass
class HapticOutput:
    force_n: np.ndarray  # (3,) device frame; always finite; |f| <= limits.max_force_n
    proxy_A: np.ndarray  # (3,) probe centre, molecule frame
    goal_A: np.ndarray  # (3,) device tip mapped to the molecule frame
    touched_atoms: tuple[int, ...]  # atoms the proxy touches (0-3); first one = "the touched atom"
    contact: bool
    clamped: bool
    drifting: bool
    fault: bool  # non-finite/invalid input -> zero force and fault=True
    cube_center_A: np.ndarray
    cube_half_A: float
    seated: bool = True  # False while the proxy waits for the goal to reach free space
    iterations: int = 0  # proxy path steps this tick
    # the clutch is held: the probe stays, the cube follows the hand, no force
    clutched: bool = False


class HapticEngine:
    """Contact force of the probe sphere on the SAS of one structure (see module docstring)."""

    def __init__(
        self, structure: Structure, limits: DeviceLimits, settings: HapticSettings | None = None
    ):
        self._limits = limits
        self._settings = (settings or HapticSettings()).validated(limits)
        self._structure = structure
        self._last_t_ns: int | None = None
        self._last_tip: tuple[float, float, float] | None = None
        self._last_goal = (0.0, 0.0, 0.0)
        self._last_proxy = (0.0, 0.0, 0.0)
        self._last_touched: tuple[int, ...] = ()
        self._clutched = False
        self._build_geometry()
        self._mapping = self._initial_mapping()

    # ------------------------------------------------------------- properties
    @property
    def settings(self) -> HapticSettings:
        return replace(self._settings)

    @property
    def mapping(self) -> WorkspaceMapping:
        """The live workspace mapping (read-only for callers)."""
        return self._mapping

    @property
    def grid(self) -> UniformGrid:
        """The uniform grid of expanded spheres the contact is computed on."""
        return self._grid

    @property
    def structure(self) -> Structure:
        return self._structure

    @property
    def limits(self) -> DeviceLimits:
        return self._limits

    # -------------------------------------------------------------- life cycle
    def reset(self) -> None:
        """After a fault or reconnect: the proxy is unseated (zero force until the goal is
        in free space, then it is seated at the goal) and the next tick has dt = 0. The
        navigation cube stays where it is."""
        self._solver.unseat()
        self._last_t_ns = None

    def update(self, **changes) -> None:
        """Change settings by HapticSettings field name; ValueError (nothing changed) on bad
        values."""
        names = {f.name for f in fields(HapticSettings)}
        for name in changes:
            if name not in names:
                raise ValueError(
                    f"unknown haptic setting {name!r} (known: {', '.join(sorted(names))})"
                )
        new = replace(self._settings, **changes).validated(self._limits)
        old, self._settings = self._settings, new
        if new.probe_radius_A != old.probe_radius_A:
            position = self._solver.position
            self._build_geometry()
            if position is not None and self._solver.is_free(*position):
                self._solver.position = position  # still outside the new spheres: keep it
        if new.method != old.method:
            self._solver.unseat()
        if new.cube_center_A != old.cube_center_A:
            rotation, self._mapping = self._mapping.rotation, self._initial_mapping()
            self._mapping.turn(rotation)
        elif new.cube_half_A != old.cube_half_A:
            half = initial_half(self._structure, self._limits, new.cube_half_A, new.probe_radius_A)
            self._mapping.rescale(half, self._last_tip)

    def set_view(self, rotation) -> None:
        """Turn the workspace with the view (validate_rotation's 9 floats),
        about the goal: the probe stays where it is and the molecule turns around it."""
        self._mapping.turn(rotation, self._last_tip)

    def set_clutch(self, held: bool) -> None:
        """Hold (True) or release the clutch: while held the goal stays where it was, the cube
        follows the hand and no force is rendered, so the arm can be re-centred without moving
        the probe."""
        self._clutched = bool(held)

    @property
    def clutched(self) -> bool:
        return self._clutched

    def recentre(self) -> None:
        """Centre the cube on the probe. The hand then maps elsewhere, so the proxy is unseated
        (no force until the probe is in free space, as after a reconnect)."""
        self._mapping.recentre(self._last_proxy)
        self._solver.unseat()

    def set_structure(self, structure: Structure) -> None:
        """Switch molecule: new grid, a new navigation cube (the view's turn kept), unseated
        proxy."""
        self._structure = structure
        self._build_geometry()
        rotation, self._mapping = self._mapping.rotation, self._initial_mapping()
        self._mapping.turn(rotation)
        self._last_t_ns = None

    def _build_geometry(self) -> None:
        radii = self._structure.expanded_radii(self._settings.probe_radius_A)
        self._grid = UniformGrid(self._structure.positions, radii)
        self._cache = NeighbourCache(self._grid)
        self._solver = ProxySolver(self._cache)

    def _initial_mapping(self) -> WorkspaceMapping:
        s = self._settings
        return initial_mapping(
            self._structure,
            self._limits,
            s.cube_half_A,
            s.probe_radius_A,
            s.cube_center_A,
            Surface(self._grid),
        )

    # -------------------------------------------------------------------- tick
    def step(self, state: DeviceState) -> HapticOutput:
        """One control tick: the force to write for this device state."""
        try:
            tx, ty, tz = _xyz(state.position_mm)
            vx, vy, vz = _xyz(state.velocity_mm_s)
            t_ns = int(state.t_ns)
        except (TypeError, ValueError, OverflowError):
            return self._fault()
        if not (
            math.isfinite(tx)
            and math.isfinite(ty)
            and math.isfinite(tz)
            and math.isfinite(vx)
            and math.isfinite(vy)
            and math.isfinite(vz)
        ):
            return self._fault()
        dt = 0.0
        if self._last_t_ns is not None and t_ns > self._last_t_ns:
            dt = min((t_ns - self._last_t_ns) * 1e-9, MAX_DT_S)
        self._last_t_ns = t_ns
        tip = (tx, ty, tz)
        self._last_tip = tip
        mapping = self._mapping
        solver = self._solver
        if self._clutched:  # the probe stays; the cube follows the hand
            mapping.hold(self._last_goal, tip)
            return self._output(
                ZERO,
                self._last_proxy,
                self._last_goal,
                self._last_touched,
                False,
                seated=solver.seated,
                clutched=True,
            )
        drifting = mapping.advance(tx, ty, tz, dt)
        goal = mapping.to_molecule(tx, ty, tz)
        previous_goal, self._last_goal = self._last_goal, goal
        if not state.calibrated:
            solver.unseat()
            return self._output(ZERO, goal, goal, (), drifting, seated=False)
        s = self._settings
        touched: tuple[int, ...] = ()
        if s.method == "proxy":
            if not solver.seat_if_free(goal):
                return self._output(ZERO, goal, goal, (), drifting, seated=False)
            last = previous_goal
            budget = SNAP_SPEED_MM_S * max(
                dt, MIN_SNAP_DT_S
            ) * mapping.scale_A_per_mm + 2.0 * math.sqrt(
                (goal[0] - last[0]) ** 2 + (goal[1] - last[1]) ** 2 + (goal[2] - last[2]) ** 2
            )
            proxy = solver.solve(goal, budget)
            touched = tuple(sphere[0] for sphere in solver.touching)
        else:
            hit = penalty_contact(self._cache, *goal)
            proxy = goal if hit is None else hit[0]
            touched = () if hit is None else (hit[1][0],)
        force = ZERO
        if proxy != goal:  # in contact, or (proxy) still catching up after a snap
            force = contact_force(
                mapping.to_device(*proxy),
                tip,
                (vx, vy, vz),
                s.stiffness_n_per_mm,
                s.damping_n_s_per_m,
                self._limits.max_force_n,
            )
            if force.fault:
                return self._fault()
        return self._output(force, proxy, goal, touched, drifting, iterations=solver.iterations)

    def _output(
        self, force, proxy, goal, touched, drifting, seated=True, iterations=0, clutched=False
    ) -> HapticOutput:
        self._last_proxy = proxy
        self._last_touched = touched
        m = self._mapping
        c = m.cube_center
        # one array, four views: a numpy call costs more than these twelve floats
        buf = np.array((force.x, force.y, force.z, *proxy, *goal, c[0], c[1], c[2]))
        return HapticOutput(
            force_n=buf[0:3],
            proxy_A=buf[3:6],
            goal_A=buf[6:9],
            touched_atoms=touched,
            contact=bool(touched),
            clamped=force.clamped,
            drifting=drifting,
            fault=False,
            cube_center_A=buf[9:12],
            cube_half_A=m.cube_half_A,
            seated=seated,
            iterations=iterations if self._settings.method == "proxy" else 0,
            clutched=clutched,
        )

    def _fault(self) -> HapticOutput:
        m = self._mapping
        return HapticOutput(
            force_n=np.zeros(3),
            proxy_A=np.array(self._last_proxy),
            goal_A=np.array(self._last_goal),
            touched_atoms=(),
            contact=False,
            clamped=False,
            drifting=False,
            fault=True,
            cube_center_A=np.array(m.cube_center),
            cube_half_A=m.cube_half_A,
            seated=self._solver.seated,
        )


def build_engine(structure: Structure, limits: DeviceLimits, settings: dict) -> HapticEngine:
    """An engine from a settings dict (validate_settings' form): how the daemon and replays build
    one."""
    return HapticEngine(structure, limits, HapticSettings(**settings).validated(limits))
