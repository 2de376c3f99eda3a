"""Clearance and passage radius (molecule/clearance.py) against brute force, and the findings'
bottleneck on a synthetic channel of known radius.

Oracles: distances to every atom's vdW surface in numpy (no grid), dense samples of the
plane around a reported passage centre, and the geometry of a closed ring of spheres.
"""

from __future__ import annotations

import numpy as np
import pytest
from sasprobe.molecule.clearance import OPEN_RADIUS_A, ClearanceField

RING_ATOMS, RING_RADIUS, CARBON = 12, 4.2, 1.70  # Bondi's carbon: inner radius 4.2 − 1.7 = 2.5 Å
INNER = RING_RADIUS - CARBON


def brute(structure, point) -> np.ndarray:
    """Surface distance of every atom from a point."""
    return np.linalg.norm(structure.positions - point, axis=1) - structure.vdw_radii


def sas_points(structure, n: int, rng, probe: float = 1.4) -> np.ndarray:
    """Points on the SAS (a probe centre touching some atom and inside none)."""
    out = []
    while len(out) < n:
        i = rng.integers(structure.n_atoms)
        u = rng.normal(size=3)
        p = structure.positions[i] + u / np.linalg.norm(u) * (structure.vdw_radii[i] + probe)
        if brute(structure, p).min() >= probe - 1e-9:
            out.append(p)
    return np.array(out)


def test_the_passage_is_a_local_maximum_of_the_brute_force_clearance_in_its_plane(crambin):
    field = ClearanceField.of(crambin)
    rng = np.random.default_rng(7)
    bounded = 0
    for p in sas_points(crambin, 150, rng):
        t = rng.normal(size=3)
        t /= np.linalg.norm(t)
        result = field.passage(p, t)
        q = result.center_A
        d = brute(crambin, q)
        assert abs(float((q - p) @ t)) < 1e-9, "the centre stays in the plane across the path"
        assert d.min() >= brute(crambin, p).min() - 1e-12, "the climb never goes down"
        if result.open:
            assert result.radius_A == OPEN_RADIUS_A and d.min() >= OPEN_RADIUS_A - 1e-9
            continue
        bounded += 1
        assert abs(result.radius_A - d.min()) < 1e-9
        assert set(result.atoms) == set(np.flatnonzero(d <= d.min() + 0.05))
        a = np.cross(t, [1.0, 0.0, 0.0] if abs(t[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(t, a)
        around = [
            q + s * (np.cos(th) * a + np.sin(th) * b)
            for s in (1e-4, 1e-3, 1e-2, 0.1)
            for th in np.linspace(0, 2 * np.pi, 48, endpoint=False)
        ]
        best = max(brute(crambin, x).min() for x in around)
        assert best <= d.min() + 1e-9, (
            f"a point {best - d.min():.2e} Å wider lies next to the reported centre"
        )
    assert bounded >= 8, "too few closed sections to check: the sample says nothing"


def ring_structure():
    """A closed ring of carbon atoms in the xy plane around the z axis (read from a PDB file,
    then given the exact positions the file's three decimals round)."""
    from dataclasses import replace

    from sasprobe.molecule import parse_structure

    a = 2 * np.pi * np.arange(RING_ATOMS) / RING_ATOMS
    exact = np.stack(
        [RING_RADIUS * np.cos(a), RING_RADIUS * np.sin(a), np.zeros(RING_ATOMS)], axis=1
    )
    lines = [
        f"HETATM{k + 1:5d}  C   RNG A{k + 1:4d}    {x:8.3f}{y:8.3f}{z:8.3f}  1.00  0.00           C"
        for k, (x, y, z) in enumerate(exact)
    ]
    data = ("\n".join(lines) + "\nEND\n").encode()
    return replace(parse_structure(data, name="ring", source="test:ring"), positions=exact), data


def ring_track(probe_radius: float = CARBON):
    """A probe of the ring atoms' size sliding along the inner wall through the ring (1 kHz ticks,
    2 mÅ apart along z, touching at z = 0: 0.8 Å off the axis)."""
    from sasprobe.daemon.findings.session import track_of_arrays

    structure, data = ring_structure()
    z = np.round(np.linspace(-6.0, 6.0, 6001), 9)
    n = z.size
    proxy = np.stack([np.full(n, INNER - probe_radius), np.zeros(n), z], axis=1)
    return track_of_arrays(
        structure=structure,
        structure_file=data,
        probe_radius_A=probe_radius,
        rate_hz=1000.0,
        t_s=np.arange(n) / 1000.0,
        dt_s=np.full(n, 1e-3),
        seq=np.arange(n),
        proxy_A=proxy,
        force_N=np.full(n, 0.5),
        contact=np.ones(n, dtype=bool),
        touched_atom=np.zeros(n, dtype=np.int64),
    )


def test_a_ring_channel_gives_its_inner_radius_and_the_verdicts_either_side():
    from sasprobe.daemon.findings import analyse
    from sasprobe.daemon.findings.bottleneck import verdict

    track = ring_track()
    s = track.structure
    assert np.allclose(s.vdw_radii, CARBON)
    found = analyse(track).found
    neck = found["bottleneck"]
    assert neck["radius_A"] == pytest.approx(INNER, abs=1e-9)
    assert np.allclose(
        neck["center_A"], [0.0, 0.0, 0.0], atol=1e-6
    )  # on the axis, in the ring plane
    assert neck["t_s"] == pytest.approx(3.0, abs=1e-9)
    assert sorted(a["index"] for a in neck["atoms"]) == list(
        range(RING_ATOMS)
    )  # the whole ring lines it
    for point in found["path"]["points"]:  # the profile: the widest sphere on the axis at height z
        z = point["position_A"][2]
        want = np.hypot(RING_RADIUS, z) - CARBON
        if want < OPEN_RADIUS_A - 1e-6:
            assert point["passage_A"] == pytest.approx(want, abs=1e-9)
    assert found["verdict"]["passes"]  # the session's own probe went through
    assert verdict(neck["radius_A"], INNER - 0.01)["passes"]
    above = verdict(neck["radius_A"], INNER + 0.01)
    assert not above["passes"] and "does not fit" in above["verdict"]


def test_the_live_readout_follows_the_ring():
    from sasprobe.protocol.pose import FLAG_CONTACT, Pose
    from sasprobe.render.follow.live_clearance import LiveClearance

    track = ring_track()
    (ring,) = track.blocks()  # the whole ring, one block in memory
    live = LiveClearance()
    poses = [
        Pose(seq=int(i), proxy_A=ring.proxy_A[i], flags=FLAG_CONTACT)
        for i in range(0, len(ring), 25)
    ]
    for start in range(0, len(poses), 4):  # a few poses per frame
        live.update(track.structure, 1.7, poses[start : start + 4])
        if live.passage_A is not None and live.passage_A < OPEN_RADIUS_A:
            z = live._evaluated[2]
            assert live.passage_A == pytest.approx(np.hypot(RING_RADIUS, z) - CARBON, abs=1e-9)
    last = ring.proxy_A[poses[-1].seq]
    assert live.clearance_A == pytest.approx(brute(track.structure, last).min(), abs=1e-12)
    assert live.bottleneck_A == pytest.approx(INNER, abs=1e-9)  # the pose at z = 0 was evaluated
    live.update(track.structure, 1.4, poses[:2])  # another probe radius: a new running bottleneck
    assert live.bottleneck_A is None
