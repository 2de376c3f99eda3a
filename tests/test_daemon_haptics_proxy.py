"""The god-object proxy against independent references: never inside, rests at the
brute-force constrained nearest point, and the penalty baseline's pop-through."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sasprobe.daemon.haptics.neighbours import NeighbourCache
from sasprobe.daemon.haptics.proxy import ProxySolver
from sasprobe.molecule import UniformGrid, load_default, load_structure

from tests.references.haptics import (
    constrained_candidates,
    is_local_min,
    local_minima,
    nearest_free_point,
    signed_distance,
)

CRAMBIN = load_default()


def solver_for(centers, radii) -> ProxySolver:
    return ProxySolver(
        NeighbourCache(UniformGrid(np.asarray(centers, float), np.asarray(radii, float)))
    )


def drive(solver: ProxySolver, start, goal, ticks_in: int = 60, ticks_hold: int = 40) -> np.ndarray:
    """Seat at `start` (free), move the goal in a straight line to `goal`, hold it there."""
    assert solver.seat_if_free(tuple(start))
    for k in range(1, ticks_in + 1):
        solver.solve(tuple(start + (goal - start) * k / ticks_in))
    for _ in range(ticks_hold):
        solver.solve(tuple(goal))
    return np.array(solver.position)


def random_cluster(rng, n: int):
    """n mutually overlapping spheres (expanded-atom sizes) and a goal just inside their seam."""
    radii = rng.uniform(2.9, 3.4, n)
    centers = [np.zeros(3)]
    while len(centers) < n:
        c = rng.normal(size=3)
        c = c / np.linalg.norm(c) * rng.uniform(1.2, 3.8)
        if all(np.linalg.norm(c - o) < radii[0] + radii[1] - 0.3 for o in centers):
            centers.append(c)
    centers = np.array(centers)
    return centers, radii


def seam_goal(rng, centers, radii) -> np.ndarray | None:
    """A goal 0.1-1.5 Å inside the union: under a random point of the sphere (one sphere),
    of the intersection circle (two) or under the triple point (three)."""
    for _ in range(200):
        if len(centers) == 1:
            u = rng.normal(size=3)
            surface = centers[0] + radii[0] * u / np.linalg.norm(u)
        else:
            # a random free point where all the spheres meet: the reference's candidates
            # for a far goal in a random direction include circle and triple points
            far = centers.mean(axis=0) + rng.normal(size=3) * 50.0
            cands = constrained_candidates(centers, radii, far)
            on_all = [
                c
                for c in cands
                if np.all(np.abs(np.linalg.norm(centers - c, axis=1) - radii) < 1e-9)
            ]
            if not on_all:
                continue
            surface = on_all[rng.integers(len(on_all))]
        normals = (surface - centers) / radii[:, None]
        inward = -normals.sum(axis=0)
        g = surface + inward / np.linalg.norm(inward) * rng.uniform(0.1, 1.5)
        if signed_distance(g, centers, radii)[0] < -0.05:
            return g
    return None


@pytest.mark.parametrize("n_spheres", [1, 2, 3])
def test_rest_point_is_the_brute_force_constrained_minimum(n_spheres):
    """From any side the proxy comes to rest at one of the reference's local minima (the far
    side of a cluster has its own); pressed in from the side of the global nearest point, it
    rests exactly there."""
    rng = np.random.default_rng(100 + n_spheres)
    for trial in range(25):
        while True:
            centers, radii = random_cluster(rng, n_spheres)
            g = seam_goal(rng, centers, radii)
            if g is not None:
                break
        minima = local_minima(centers, radii, g, rng)
        best = nearest_free_point(centers, radii, g)
        assert np.linalg.norm(minima - best, axis=1).min() < 1e-9  # the global one is a local one
        outward = (best - g) / np.linalg.norm(best - g)
        approaches = [outward] + [v / np.linalg.norm(v) for v in rng.normal(size=(3, 3))]
        for k, u in enumerate(approaches):
            p = drive(solver_for(centers, radii), g + 14.0 * u, g)
            assert signed_distance(p, centers, radii)[0] >= -1e-9
            gap = np.linalg.norm(minima - p, axis=1).min()
            assert gap < 1e-7, (
                f"trial {trial}: rest point {p} is not a brute-force local minimum "
                f"({gap:.2e} Å off)"
            )
            assert is_local_min(p, g, centers, radii, rng)
            if k == 0:
                assert np.linalg.norm(p - best) < 1e-7, (
                    f"trial {trial}: not the global nearest point"
                )


def test_pressing_straight_in_rests_at_the_global_nearest_point_on_crambin():
    centers, radii = CRAMBIN.positions, CRAMBIN.expanded_radii(1.4)
    rng = np.random.default_rng(7)
    checked = 0
    touched_counts = set()
    for _ in range(3000):
        i = rng.integers(len(centers))
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        surface = centers[i] + radii[i] * u
        if signed_distance(surface, centers, radii)[0] < -1e-6:
            continue  # buried part of that sphere
        depth = rng.uniform(0.2, 1.2)
        v = rng.normal(size=3)  # an oblique push: the nearest point is often on a seam
        v = v / np.linalg.norm(v) + u
        g = surface - depth * v / np.linalg.norm(v)
        # The nearest free point is within `depth` of g (the surface point is free), so
        # only spheres reaching that far can carry it; feasibility is checked on all atoms.
        near = np.linalg.norm(centers - g, axis=1) - radii <= depth + 1e-6
        cands = constrained_candidates(centers[near], radii[near], g)
        cands = cands[signed_distance(cands, centers, radii) >= -1e-9]
        best = cands[np.argmin(np.linalg.norm(cands - g, axis=1))]
        start = best + 0.5 * (best - g) / np.linalg.norm(best - g)
        if signed_distance(start, centers, radii)[0] <= 0:
            continue
        solver = solver_for(centers, radii)
        p = drive(solver, start, g)
        assert np.linalg.norm(p - best) < 1e-7
        touched_counts.add(len(solver.touching))
        checked += 1
        if checked == 60:
            break
    assert checked == 60
    assert touched_counts >= {1, 2}  # sphere and seam contacts were both exercised


@pytest.mark.parametrize("entry", ["1crn", "1oky"])
def test_proxy_never_enters_the_sas_in_long_random_sessions(entry, reference_by_id):
    structure = load_structure(reference_by_id[entry].path)
    centers, radii = structure.positions, structure.expanded_radii(1.4)
    grid = UniformGrid(centers, radii)
    solver = ProxySolver(NeighbourCache(grid))
    rng = np.random.default_rng(3)
    lo, hi = centers.min(axis=0), centers.max(axis=0)
    goal = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] + 8.0])
    assert solver.seat_if_free(tuple(goal))
    velocity = np.zeros(3)
    worst = np.inf
    contacts = 0
    for k in range(6000):
        # a smooth random walk with occasional jumps, pulled toward the molecule
        velocity = (
            0.97 * velocity + rng.normal(size=3) * 0.03 + (centers.mean(axis=0) - goal) * 1e-4
        )
        goal = goal + velocity
        if k % 500 == 499:
            goal = goal + rng.normal(size=3) * 3.0  # a glitchy device: big jump
        p = np.array(solver.solve(tuple(goal)))
        near = grid.spheres_within(p, 1.0)
        if near.size:
            worst = min(worst, float(signed_distance(p, centers[near], radii[near])[0]))
        contacts += bool(solver.touching)
    assert worst >= -1e-9
    assert contacts > 1000  # the walk really pressed into the surface


def test_proxy_never_enters_the_sas_in_scripted_sessions():
    from sasprobe.daemon.haptics import HapticEngine, HapticSettings
    from sasprobe.devices.base import PHANTOM_OMNI_LIMITS
    from sasprobe.devices.registry import open_device

    centers, radii = CRAMBIN.positions, CRAMBIN.expanded_radii(1.4)
    for script in ("scan", "dive", "press", "orbit", "random"):
        device = open_device(f"sim:{script}", structure=CRAMBIN, seed=5, cube_half_A="fit")
        engine = HapticEngine(CRAMBIN, PHANTOM_OMNI_LIMITS, HapticSettings(cube_half_A="fit"))
        device.open()
        proxies = []
        contacts = 0
        for _ in range(min(int(device.hand_path.duration_s * 1000), 5000)):
            out = engine.step(device.read())
            device.write_force(out.force_n)
            if out.seated:
                proxies.append(out.proxy_A)
            contacts += out.contact
        device.close()
        assert contacts > 200, script
        assert signed_distance(np.array(proxies), centers, radii).min() >= -1e-9, script


def sheet(spacing: float = 2.0, n: int = 9) -> np.ndarray:
    """A flat single layer of carbon atoms in the z = 0 plane: a thin part of SAS."""
    xs = (np.arange(n) - (n - 1) / 2) * spacing
    x, y = np.meshgrid(xs, xs)
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])


@pytest.mark.parametrize("method", ["proxy", "penalty"])
def test_pushing_through_a_thin_sheet_pops_through_only_with_the_penalty_method(method):
    from sasprobe.daemon.haptics import HapticEngine, HapticSettings
    from sasprobe.devices.base import PHANTOM_OMNI_LIMITS, DeviceState

    from tests.references.haptics import synthetic_structure

    structure = synthetic_structure(
        sheet() + [0.3, 0.2, 0.0]
    )  # off-centre: not a symmetric balance
    engine = HapticEngine(
        structure, PHANTOM_OMNI_LIMITS, HapticSettings(method=method, cube_half_A=12.0)
    )
    m = engine.mapping
    start = np.array(m.to_device(0.0, 0.0, 6.0))
    end = np.array(m.to_device(0.0, 0.0, -6.0))  # straight through the sheet, out the far side
    pushed_along = 0.0
    lowest_proxy = np.inf
    for k in range(1201):
        tip = start + (end - start) * k / 1200
        out = engine.step(DeviceState(t_ns=k * 1_000_000, position_mm=tip))
        pushed_along = max(pushed_along, -out.force_n[2])  # force component along the push (-z)
        if out.contact:
            lowest_proxy = min(lowest_proxy, out.proxy_A[2])
    if method == "penalty":
        assert pushed_along > 0.5  # the surface flipped: it pulls the hand through the sheet
        assert lowest_proxy < 0.0  # the rendered surface point went to the far side
    else:
        assert pushed_along <= 1e-12  # the force always opposes the push
        assert lowest_proxy > 0.0  # the proxy stays on the near side
        assert out.contact and out.clamped  # still held back, at the device's force limit


def test_press_script_on_crambin_pops_through_with_penalty_not_with_proxy():
    from sasprobe.daemon.haptics import HapticEngine, HapticSettings
    from sasprobe.devices.base import PHANTOM_OMNI_LIMITS
    from sasprobe.devices.registry import open_device
    from sasprobe.devices.simulated.arm import ArmModel

    along = {}
    for method in ("proxy", "penalty"):
        # A hand that pushes without limit (a person stops at the arm's rating): the test of a wall
        device = open_device(
            "sim:press",
            structure=CRAMBIN,
            cube_half_A="fit",
            arm=ArmModel(max_hand_force_n=math.inf),
        )
        push = np.array(device.hand_path.info["push_direction"])
        engine = HapticEngine(
            CRAMBIN, PHANTOM_OMNI_LIMITS, HapticSettings(method=method, cube_half_A="fit")
        )
        device.open()
        worst = -np.inf
        for _ in range(int(device.hand_path.duration_s * 1000)):
            out = engine.step(device.read())
            device.write_force(out.force_n)
            worst = max(worst, float(out.force_n @ push))
        along[method] = worst
    assert along["penalty"] > 0.2  # pulled along the push: popped through
    assert along["proxy"] <= 1e-9


def test_a_long_jump_of_the_goal_is_followed_at_once_and_stops_at_first_contact():
    centers, radii = CRAMBIN.positions, CRAMBIN.expanded_radii(1.4)
    solver = solver_for(centers, radii)
    top = centers[np.argmax(centers[:, 2] + radii)]
    start = np.array([top[0], top[1], centers[:, 2].max() + 60.0])
    assert solver.seat_if_free(tuple(start))
    far_free = start + np.array([6.0, -5.0, 40.0])
    assert np.allclose(solver.solve(tuple(far_free)), far_free)  # 41 Å of free flight in one tick
    assert solver.iterations == 1
    # one jump down through the molecule: with a travel budget just beyond the first
    # contact, the proxy stops exactly where the segment first meets the SAS (brute force:
    # the smallest ray parameter over all spheres)
    below = np.array([top[0], top[1], centers[:, 2].min() - 30.0])
    d = below - far_free
    w = far_free - centers
    b = w @ d
    c = (w * w).sum(axis=1) - radii**2
    disc = b * b - (d @ d) * c
    t = (-b[disc > 0] - np.sqrt(disc[disc > 0])) / (d @ d)
    t = t[t >= 0].min()
    first = far_free + t * d
    p = np.array(solver.solve(tuple(below), budget_A=t * np.linalg.norm(d) + 1e-9))
    assert np.linalg.norm(p - first) < 1e-6
    assert len(solver.touching) == 1


def test_degenerate_clusters_never_trap_or_cycle_the_proxy():
    """Coplanar centres, equal radii and duplicate atoms make circles tangent to spheres and
    four spheres meet at a point; the proxy must stay outside and converge (no cycling to
    the iteration cap)."""
    from sasprobe.daemon.haptics.proxy import MAX_ITERATIONS

    rng = np.random.default_rng(21)
    for _ in range(24):
        n = int(rng.integers(3, 40))
        box = rng.uniform(3, 10)
        centers = rng.uniform(-box, box, (n, 3))
        centers[:, 2] = 0.0  # all in one plane
        centers = np.round(centers)  # on a lattice: many symmetric triples
        centers[1] = centers[0]
        radii = np.full(n, 3.1)
        solver = solver_for(centers, radii)
        goal = np.array([0.0, 0.0, box + 8.0])
        assert solver.seat_if_free(tuple(goal))
        velocity = np.zeros(3)
        for _ in range(500):
            velocity = 0.95 * velocity + rng.normal(size=3) * 0.05 - goal * 0.002
            goal = goal + velocity
            p = np.array(solver.solve(tuple(goal), rng.uniform(0.05, 1.0)))
            assert signed_distance(p, centers, radii)[0] >= -1e-9
            assert solver.iterations < MAX_ITERATIONS
