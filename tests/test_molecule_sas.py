"""`sasprobe sas` against FreeSASA with identical radii and probe."""

from __future__ import annotations

import json

import freesasa
import numpy as np
import pytest
from sasprobe.molecule import UniformGrid, load_default, load_structure
from sasprobe.molecule.sas import ACCESSIBLE_MIN_AREA, shrake_rupley

from tests.conftest import run_cli


def freesasa_areas(structure, probe=1.4) -> np.ndarray:
    """Lee-Richards areas from FreeSASA on exactly our centres and vdW radii."""
    params = freesasa.Parameters(
        {"algorithm": freesasa.LeeRichards, "probe-radius": probe, "n-slices": 100}
    )
    result = freesasa.calcCoord(structure.positions.ravel(), structure.vdw_radii, params)
    return np.array([result.atomArea(i) for i in range(structure.n_atoms)])


@pytest.mark.parametrize("entry_id", ["1crn", "1oky", "1tii", "3sn6"])
def test_sas_agrees_with_freesasa(reference_by_id, entry_id):
    structure = load_structure(reference_by_id[entry_id].path)
    reference = freesasa_areas(structure)
    result = shrake_rupley(UniformGrid(structure.positions, structure.expanded_radii(1.4)))
    assert result.total == pytest.approx(reference.sum(), rel=0.01)
    agree = np.mean(result.accessible == (reference >= ACCESSIBLE_MIN_AREA))
    assert agree >= 0.99, f"{entry_id}: accessible flags agree on {agree:.4f}"


def test_isolated_and_buried_spheres_are_exact():
    # one lone sphere: 4 pi R^2; a small sphere inside a big one: 0
    centers = np.array([[0.0, 0, 0], [50.0, 0, 0], [50.2, 0, 0]])
    radii = np.array([2.0, 3.0, 1.0])
    result = shrake_rupley(UniformGrid(centers, radii), n_points=64, refine_points=64)
    assert result.areas[0] == pytest.approx(4 * np.pi * 4.0)
    assert result.areas[2] == 0.0 and not result.accessible[2]
    assert result.areas[1] == pytest.approx(4 * np.pi * 9.0)


def test_two_sphere_lens_matches_the_analytic_cap_area():
    # sphere 0 loses the cap of height h = R - (R^2 + d^2 - r^2) / (2 d): area 2 pi R h
    R, r, d = 3.0, 2.5, 3.5
    result = shrake_rupley(
        UniformGrid(np.array([[0.0, 0, 0], [d, 0, 0]]), np.array([R, r])), 4096, 4096
    )
    h = R - (R**2 + d**2 - r**2) / (2 * d)
    assert result.areas[0] == pytest.approx(4 * np.pi * R**2 - 2 * np.pi * R * h, rel=2e-3)


def test_cli_json_reports_radii_areas_and_flags():
    out = run_cli("sas", "--json", "--probe-radius", "1.2")
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    atoms = data["atoms"]
    crambin = load_default()
    assert data["n_atoms"] == crambin.n_atoms == len(atoms["area"])
    np.testing.assert_allclose(atoms["expanded_radius"], crambin.vdw_radii + 1.2)
    np.testing.assert_allclose(sum(atoms["area"]), data["total_area"], rtol=1e-6)
    assert data["n_accessible"] == sum(atoms["accessible"])
    human = run_cli("sas")
    assert human.returncode == 0 and "Å²" in human.stdout


@pytest.mark.parametrize("args", [["--probe-radius", "0"], ["--points", "3"], ["--points", "x"]])
def test_cli_bad_options(args):
    out = run_cli("sas", *args)
    assert (
        out.returncode == 2
        and len(out.stderr.strip().splitlines()) == 1
        and "Traceback" not in out.stderr
    )
