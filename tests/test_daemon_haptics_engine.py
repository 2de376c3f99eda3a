"""HapticEngine: settings validation, faults, clamping, determinism, seams, drift."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sasprobe.daemon.haptics import HapticEngine, HapticOutput, HapticSettings
from sasprobe.daemon.haptics.force_law import contact_force
from sasprobe.devices.base import PHANTOM_OMNI_LIMITS, DeviceState
from sasprobe.devices.registry import open_device
from sasprobe.devices.workspace.start import initial_mapping
from sasprobe.molecule import load_default

from tests.references.haptics import synthetic_structure

CRAMBIN = load_default()
LIMITS = PHANTOM_OMNI_LIMITS
FIT = HapticSettings(
    cube_half_A="fit"
)  # the whole of crambin in the cube (these tests press on any atom)


def state(k: int, tip, velocity=(0.0, 0.0, 0.0), **kw) -> DeviceState:
    return DeviceState(
        t_ns=k * 1_000_000,
        position_mm=np.asarray(tip, float),
        velocity_mm_s=np.asarray(velocity, float),
        **kw,
    )


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "changes, words",
    [
        ({"probe_radius_A": 0.0}, "probe radius"),
        ({"probe_radius_A": -1.4}, "probe radius"),
        ({"probe_radius_A": 50.0}, "probe radius"),
        ({"probe_radius_A": float("nan")}, "probe radius"),
        ({"stiffness_n_per_mm": 0.71}, "stiffness"),
        ({"stiffness_n_per_mm": 0.0}, "stiffness"),
        ({"stiffness_n_per_mm": float("inf")}, "stiffness"),
        ({"damping_n_s_per_m": -0.1}, "damping"),
        ({"damping_n_s_per_m": 6.0}, "damping"),
        ({"method": "magic"}, "method"),
        ({"cube_half_A": 0.0}, "cube"),
        ({"cube_half_A": float("nan")}, "cube"),
        ({"cube_center_A": (1.0, float("inf"), 0.0)}, "cube"),
        ({"probe_radius_A": "wide"}, "probe radius"),
    ],
)
def test_bad_settings_are_one_clear_value_error(changes, words):
    with pytest.raises(ValueError) as err:
        HapticEngine(CRAMBIN, LIMITS, HapticSettings(**changes))
    message = str(err.value)
    assert words in message and "\n" not in message
    engine = HapticEngine(CRAMBIN, LIMITS)
    before = engine.settings
    with pytest.raises(ValueError):
        engine.update(**changes)
    assert engine.settings == before  # nothing changed


def test_update_rejects_unknown_names_and_accepts_good_values():
    engine = HapticEngine(CRAMBIN, LIMITS)
    with pytest.raises(ValueError, match="unknown haptic setting"):
        engine.update(stiffnes=0.2)
    engine.update(stiffness_n_per_mm=0.7, method="penalty", probe_radius_A=1.0)
    s = engine.settings
    assert (s.stiffness_n_per_mm, s.method, s.probe_radius_A) == (0.7, "penalty", 1.0)
    assert np.allclose(engine.grid.radii, CRAMBIN.vdw_radii + 1.0)  # the grid follows the probe


def test_default_settings_are_valid_and_well_under_the_device_limit():
    s = HapticSettings().validated(LIMITS)
    assert 0 < s.stiffness_n_per_mm <= 0.5 * LIMITS.max_stiffness_n_per_mm
    assert s.probe_radius_A == 1.4 and s.method == "proxy"


@pytest.mark.parametrize(
    "bad",
    [
        dict(position_mm=np.array([np.nan, 0.0, 0.0])),
        dict(position_mm=np.array([0.0, np.inf, 0.0])),
        dict(velocity_mm_s=np.array([0.0, 0.0, -np.inf])),
        dict(position_mm=np.array([1.0, 2.0])),
        dict(position_mm=None),
    ],
)
def test_non_finite_or_malformed_input_gives_zero_force_and_a_fault(bad):
    engine = HapticEngine(CRAMBIN, LIMITS, FIT)
    m = engine.mapping
    inside = np.array(m.to_device(*CRAMBIN.positions[0]))
    outside = inside + [0, 0, 60.0]
    for k, tip in enumerate(np.linspace(outside, inside, 400)):  # press into the surface
        out = engine.step(state(k, tip))
    assert out.contact and np.linalg.norm(out.force_n) > 0.5
    proxy_before = out.proxy_A.copy()
    fields = dict(t_ns=400 * 1_000_000, position_mm=inside, velocity_mm_s=np.zeros(3))
    fields.update(bad)
    out = engine.step(DeviceState(**fields))
    assert out.fault and not out.contact
    assert np.array_equal(out.force_n, np.zeros(3))
    assert np.array_equal(out.proxy_A, proxy_before)
    out = engine.step(state(401, inside))  # recovers: the proxy kept its place, no pop-through
    assert not out.fault and out.contact and np.linalg.norm(out.force_n) > 0.5


def test_uncalibrated_device_gets_no_force():
    engine = HapticEngine(CRAMBIN, LIMITS, FIT)
    inside = np.array(engine.mapping.to_device(*CRAMBIN.positions[0]))
    out = engine.step(state(0, inside, calibrated=False))
    assert np.array_equal(out.force_n, np.zeros(3)) and not out.fault and not out.seated


def test_forces_are_finite_and_clamped_for_wild_input():
    rng = np.random.default_rng(11)
    for method in ("proxy", "penalty"):
        engine = HapticEngine(
            CRAMBIN, LIMITS, HapticSettings(method=method, stiffness_n_per_mm=0.7)
        )
        clamped = 0
        for k in range(3000):
            scale = 10.0 ** rng.integers(-1, 7)  # up to a million mm: a garbled reading
            tip = rng.normal(size=3) * scale if k % 7 == 0 else rng.normal(size=3) * 15
            out = engine.step(state(k, tip, rng.normal(size=3) * 1e3))
            assert np.all(np.isfinite(out.force_n))
            assert np.linalg.norm(out.force_n) <= LIMITS.max_force_n * (1 + 1e-12)
            clamped += out.clamped
            assert out.clamped == (np.linalg.norm(out.force_n) >= LIMITS.max_force_n * (1 - 1e-12))
        assert clamped > 0


def test_force_law_against_hand_calculation():
    f = contact_force((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.3, 0.0, 3.3)
    assert (f.x, f.y, f.z, f.clamped, f.fault) == (0.0, 0.0, pytest.approx(0.6), False, False)
    # damping opposes the velocity along the spring: tip moving down into the surface at 100 mm/s
    f = contact_force((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (0.0, 0.0, -100.0), 0.3, 2.0, 3.3)
    assert f.z == pytest.approx(0.6 + 2.0 * 0.1)
    # sliding along the surface is not damped
    f = contact_force((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (100.0, 0.0, 0.0), 0.3, 2.0, 3.3)
    assert (f.x, f.z) == (0.0, pytest.approx(0.6))
    f = contact_force((0.0, 3.0, 4.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0, 0.0, 3.3)
    assert (
        f.clamped
        and math.hypot(f.y, f.z) == pytest.approx(3.3)
        and f.y / f.z == pytest.approx(0.75)
    )
    f = contact_force((0.0, 0.0, 1e308), (0.0, 0.0, -1e308), (0.0, 0.0, 0.0), 0.7, 0.0, 3.3)
    assert f.fault and (f.x, f.y, f.z) == (0.0, 0.0, 0.0)


# ---------------------------------------------------------------- determinism
def run_session(script: str, method: str, ticks: int) -> list[HapticOutput]:
    device = open_device(f"sim:{script}", structure=CRAMBIN, seed=9)
    engine = HapticEngine(CRAMBIN, LIMITS, HapticSettings(method=method))
    device.open()
    outs = []
    for _ in range(ticks):
        out = engine.step(device.read())
        device.write_force(out.force_n)
        outs.append(out)
    return outs


@pytest.mark.parametrize("method", ["proxy", "penalty"])
def test_step_is_deterministic_bit_for_bit(method):
    a = run_session("random", method, 3000)
    b = run_session("random", method, 3000)
    for x, y in zip(a, b):
        assert np.array_equal(x.force_n, y.force_n) and np.array_equal(x.proxy_A, y.proxy_A)
        assert x.touched_atoms == y.touched_atoms and x.clamped == y.clamped
    assert sum(o.contact for o in a) > 300
    # Replaying the recorded states into a fresh engine gives the same outputs.
    device = open_device("sim:random", structure=CRAMBIN, seed=9)
    device.open()
    states = []
    for out in a:
        states.append(device.read())
        device.write_force(out.force_n)
    engine = HapticEngine(CRAMBIN, LIMITS, HapticSettings(method=method))
    for s, out in zip(states, a):
        again = engine.step(s)
        assert np.array_equal(again.force_n, out.force_n)


def test_reset_unseats_the_proxy_until_the_goal_is_free():
    engine = HapticEngine(CRAMBIN, LIMITS, FIT)
    m = engine.mapping
    inside = np.array(m.to_device(*CRAMBIN.positions[0]))
    outside = inside + [0, 0, 60.0]
    path = np.linspace(outside, inside, 300)
    for k, tip in enumerate(path):
        out = engine.step(state(k, tip))
    assert out.contact
    engine.reset()
    out = engine.step(state(300, inside))
    assert not out.seated and np.array_equal(out.force_n, np.zeros(3))  # no kick on reconnect
    for k, tip in enumerate(path[::-1]):  # back out ...
        out = engine.step(state(301 + k, tip))
    assert out.seated
    for k, tip in enumerate(path):  # ... and the surface is there again
        out = engine.step(state(601 + k, tip))
    assert out.contact and np.linalg.norm(out.force_n) > 0.5


def test_set_structure_refits_the_cube_and_unseats():
    engine = HapticEngine(CRAMBIN, LIMITS)
    small = synthetic_structure([[0, 0, 0], [1.5, 0, 0]])
    engine.set_structure(small)
    assert engine.structure is small and engine.grid.centers.shape[0] == 2
    assert engine.mapping.cube_half_A < 10.0
    out = engine.step(state(0, engine.mapping.to_device(0.75, 0.0, 0.0)))
    assert not out.seated and np.array_equal(out.force_n, np.zeros(3))


# ------------------------------------------------------------------- seams
def seam_session(points, goal_path_A, method="proxy"):
    structure = synthetic_structure(points)
    engine = HapticEngine(
        structure, LIMITS, HapticSettings(method=method, cube_half_A=10.0, cube_center_A=(0, 0, 0))
    )
    m = engine.mapping
    forces, contacts = [], []
    for k, g in enumerate(goal_path_A):
        out = engine.step(state(k, m.to_device(*g)))
        forces.append(out.force_n)
        contacts.append(out.touched_atoms)
    return np.array(forces), contacts, m.scale_A_per_mm


def goal_path(points, depth: float, ticks: int = 1500):
    """Approach from above, then slide along x at a constant depth under the top surface."""
    points = np.asarray(points, float)
    radius = 1.7 + 1.4
    xs = np.linspace(points[:, 0].min() - 1.5, points[:, 0].max() + 1.5, ticks)
    top = [
        max(p[2] + math.sqrt(max(radius**2 - (x - p[0]) ** 2 - p[1] ** 2, 0)) for p in points)
        for x in xs
    ]
    z = np.array(top) - depth
    approach = [np.array([xs[0], 0.0, z[0] + 4.0 - 4.0 * k / 200]) for k in range(200)]
    return approach + [np.array([x, 0.0, zz]) for x, zz in zip(xs, z)]


@pytest.mark.parametrize(
    "points",
    [
        [[-1.5, 0, 0], [1.5, 0, 0]],  # two spheres: one seam
        [[-2.6, 0, 0], [0, 0, -0.8], [2.6, 0, 0]],  # three: two seams in a row
        [[-1.4, -0.8, 0], [1.4, -0.8, 0], [0, 1.6, -0.2]],  # three meeting at a point
    ],
)
def test_force_is_continuous_while_the_goal_slides_across_seams(points):
    path = goal_path(points, depth=0.6)
    forces, contacts, scale = seam_session(points, path)
    steps = np.linalg.norm(np.diff(np.array(path), axis=0), axis=1).max() / scale  # mm per tick
    jumps = np.linalg.norm(np.diff(forces, axis=0), axis=1)
    k = HapticSettings().validated(LIMITS).stiffness_n_per_mm  # the engine's default
    seams = {len(c) for c in contacts}
    assert 2 in seams  # the proxy did sit in a seam on the way
    # Lipschitz: the force changes by at most a few times K times the goal's step.
    assert jumps.max() <= 4.0 * k * steps, jumps.max()
    penalty, _, _ = seam_session(points, path, method="penalty")
    # the baseline jumps where the nearest sphere changes (what the proxy avoids)
    assert np.linalg.norm(np.diff(penalty, axis=0), axis=1).max() > 5 * jumps.max()


# ------------------------------------------------------------------ drift
def test_drift_moves_the_cube_without_a_force_jump():
    points = np.array(
        [[x, y, 0.0] for x in np.arange(-40, 41, 2.0) for y in np.arange(-40, 41, 2.0)]
    )
    structure = synthetic_structure(points)  # a wide flat floor to slide on while drifting
    engine = HapticEngine(
        structure, LIMITS, HapticSettings(cube_half_A=15.0, cube_center_A=(0, 0, 0))
    )
    m = engine.mapping
    core = m.core_half_mm
    floor = np.array(m.to_device(0, 0, 3.1))[2] - 1.0  # pressed 1 mm into the floor
    start = np.array([0.0, 0.0, floor])
    for k in range(200):  # touch down from 10 mm above
        engine.step(state(k, start + [0, 0, 10.0 * (1 - k / 199)]))
    forces, drifting, centers = [], [], []
    for k in range(3000):
        x = min(k * 0.02, core + 3.0)  # 20 mm/s toward +x, into the margin, then held there
        out = engine.step(
            state(200 + k, start + [x, 0, 0], velocity=(20.0 if x < core + 3 else 0.0, 0, 0))
        )
        forces.append(out.force_n)
        drifting.append(out.drifting)
        centers.append(out.cube_center_A[0])
        assert out.contact
    forces = np.array(forces)
    assert not any(drifting[: int(core / 0.02) - 5]) and any(drifting)
    assert centers[-1] > 5.0  # the molecule really moved under the hand
    # no jump when drift starts, during it, or when the hand stops: every tick's force change
    # is bounded by K times the goal's motion in that tick (hand 0.02 mm + drift <= 0.03 mm)
    jumps = np.linalg.norm(np.diff(forces, axis=0), axis=1)
    k = HapticSettings().validated(LIMITS).stiffness_n_per_mm  # the engine's default
    assert jumps.max() <= 2.0 * k * (0.02 + m.drift_speed_mm_s * 1e-3)
    first = drifting.index(True)
    assert jumps[first - 1] <= 1.5 * jumps[first - 5 : first - 1].max() + 1e-6


def test_mapping_round_trip_and_fit():
    m = initial_mapping(CRAMBIN, LIMITS, "fit")
    p = np.array([3.0, -7.0, 12.5])
    assert np.allclose(m.to_molecule(*m.to_device(*p)), p)
    # the fitted cube's drift-free core holds every expanded sphere
    r = CRAMBIN.expanded_radii(1.4)[:, None]
    dev_lo = np.array([m.to_device(*q) for q in CRAMBIN.positions - r])
    dev_hi = np.array([m.to_device(*q) for q in CRAMBIN.positions + r])
    center = np.array(m.workspace_center_mm)
    assert np.all(np.abs(dev_lo - center) <= m.core_half_mm) and np.all(
        np.abs(dev_hi - center) <= m.core_half_mm
    )
    # zooming about the tip keeps the goal where it was
    tip = (10.0, -5.0, 3.0)
    goal = m.to_molecule(*tip)
    m.rescale(5.0, tip)
    assert np.allclose(m.to_molecule(*tip), goal) and m.cube_half_A == 5.0
