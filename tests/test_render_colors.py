"""Colour schemes as drawn: every atom pixel of a flat render (colour = the atom's colour,
FXAA and edges off) shows the colour docs/viewing.md documents for that atom, read back per
pixel through the G-buffer's atom ids. The expected colours are computed here from the
documented tables and ramps (Jmol CPK, RasMol amino, Kyte-Doolittle, the polymer kinds),
not from molecule/colors.py."""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid, load_structure
from sasprobe.molecule.sas import shrake_rupley
from sasprobe.render.app import RenderOptions, build_scene, initial_camera, make_renderer
from sasprobe.render.gl.targets import KIND_CAP, KIND_SPHERE
from sasprobe.render.lighting.settings import AOSettings, LightingSettings

SIZE = (320, 240)
CPK = {"C": "909090", "N": "3050F8", "O": "FF0D0D", "S": "FFFF30"}  # Jmol
RASMOL = {
    ("ASP", "GLU"): (230, 10, 10),
    ("CYS", "MET"): (230, 230, 0),
    ("LYS", "ARG"): (20, 90, 255),
    ("SER", "THR"): (250, 150, 0),
    ("PHE", "TYR"): (50, 50, 170),
    ("ASN", "GLN"): (0, 220, 220),
    ("GLY",): (235, 235, 235),
    ("LEU", "VAL", "ILE"): (15, 130, 15),
    ("ALA",): (200, 200, 200),
    ("TRP",): (180, 90, 180),
    ("HIS",): (130, 130, 210),
    ("PRO",): (220, 150, 130),
}
KD = {
    "ILE": 4.5,
    "VAL": 4.2,
    "LEU": 3.8,
    "PHE": 2.8,
    "CYS": 2.5,
    "MET": 1.9,
    "ALA": 1.8,
    "GLY": -0.4,
    "THR": -0.7,
    "SER": -0.8,
    "TRP": -0.9,
    "TYR": -1.3,
    "PRO": -1.6,
    "HIS": -3.2,
    "GLU": -3.5,
    "GLN": -3.5,
    "ASP": -3.5,
    "ASN": -3.5,
    "LYS": -3.9,
    "ARG": -4.5,
}
POLYMER = {
    "protein": (140, 170, 220),
    "nucleic": (240, 150, 50),
    "ligand": (80, 200, 80),
    "water": (255, 140, 140),
    "ion": (170, 80, 230),
}
NUCLEOTIDES = {"A", "C", "G", "U", "DA", "DC", "DG", "DT", "DU"}


def hex_rgb(code: str) -> np.ndarray:
    return np.array([int(code[i : i + 2], 16) for i in (0, 2, 4)], dtype=float)


def linear_ramp(values, low, high, stops) -> np.ndarray:
    """Evenly spaced stops (0-255) between low and high, clamped."""
    t = np.clip((np.asarray(values, float) - low) / (high - low), 0, 1) * (len(stops) - 1)
    i = np.minimum(t.astype(int), len(stops) - 2)
    f = (t - i)[:, None]
    stops = np.asarray(stops, float)
    return stops[i] * (1 - f) + stops[i + 1] * f


def flat_render(gl, structure, scheme, clip=()):
    """(image, atom id per pixel, interior mask): the flat preset without edges or FXAA."""
    opts = RenderOptions(
        size=SIZE,
        color=scheme,
        preset="flat",
        fxaa=False,
        clip=list(clip),
        lighting=LightingSettings(shadows="off", ao=AOSettings(mode="off"), edges="off"),
    )
    scene = build_scene(structure, opts)
    renderer = make_renderer(gl, scene, SIZE, opts)
    try:
        renderer.render(initial_camera(scene, opts))
        image = renderer.read_image().astype(float)
        ids = renderer.targets.read(renderer.targets.ids)
    finally:
        renderer.release()
    atom, kind = ids[..., 0], ids[..., 1]
    inside = np.isin(kind, (KIND_SPHERE, KIND_CAP))
    same = np.ones_like(inside)
    for dy in (-1, 0, 1):  # pixels whose 3x3 neighbourhood is the same atom
        for dx in (-1, 0, 1):
            same &= np.roll(np.roll(atom, dy, 0), dx, 1) == atom
    interior = inside & same
    interior[[0, -1], :] = interior[:, [0, -1]] = False
    if scheme in ("bfactor", "sas"):
        interior[-70:, -220:] = False  # under the colour bar
    return image, atom, interior


def assert_drawn(image, atom, interior, expected: dict[int, np.ndarray], minimum: int = 50) -> None:
    """Every interior pixel of an atom in `expected` shows its colour (0-255) within a level."""
    ids = atom[interior]
    keep = np.isin(ids, list(expected))
    assert keep.sum() >= minimum, f"only {keep.sum()} pixels to check"
    want = np.array([expected[int(i)] for i in ids[keep]])
    got = image[interior][keep]
    worst = np.abs(got - np.round(want)).max()
    assert worst <= 1.0, f"a pixel is {worst} levels off its documented colour"


@pytest.fixture(scope="module")
def rb8(reference_by_id):
    return load_structure(reference_by_id["1rb8"].path)  # protein and DNA, 4 chains


@pytest.fixture(scope="module")
def oky(reference_by_id):
    return load_structure(reference_by_id["1oky"].path, keep_water=True)  # protein, ligands, waters


def residue_kind(structure, i: int, sizes: dict) -> str:
    name = str(structure.residue_names[i])
    if name == "HOH":
        return "water"
    if name in KD or name == "MSE":
        return "protein"
    if name in NUCLEOTIDES:
        return "nucleic"
    return "ion" if sizes[i] == 1 else "ligand"


def residue_sizes(structure) -> dict:
    keys = list(
        zip(
            structure.chain_ids,
            structure.residue_numbers,
            structure.insertion_codes,
            structure.residue_names,
        )
    )
    counts: dict = {}
    for k in keys:
        counts[k] = counts.get(k, 0) + 1
    return {i: counts[k] for i, k in enumerate(keys)}


def test_element_residue_and_hydrophobicity_colours(gl, rb8):
    s = rb8
    image, atom, interior = flat_render(gl, s, "element")
    assert_drawn(
        image, atom, interior, {i: hex_rgb(CPK[e]) for i, e in enumerate(s.elements) if e in CPK}
    )
    image, atom, interior = flat_render(gl, s, "residue")
    table = {name: rgb for names, rgb in RASMOL.items() for name in names}
    assert_drawn(
        image,
        atom,
        interior,
        {i: np.array(table[r]) for i, r in enumerate(s.residue_names) if r in table},
    )
    image, atom, interior = flat_render(gl, s, "hydrophobicity")
    teal, white, orange = (0, 150, 160), (255, 255, 255), (230, 120, 20)
    kd = {i: KD[r] for i, r in enumerate(s.residue_names) if r in KD}
    colours = linear_ramp(list(kd.values()), -4.5, 4.5, [teal, white, orange])
    assert_drawn(image, atom, interior, dict(zip(kd, colours)))


def test_chain_colours_carbons_by_chain_and_chain_all_every_atom(gl, rb8):
    s = rb8
    image, atom, interior = flat_render(gl, s, "chain")
    hetero = {i: hex_rgb(CPK[e]) for i, e in enumerate(s.elements) if e in CPK and e != "C"}
    assert_drawn(image, atom, interior, hetero)
    carbon_colour = {}
    for chain in np.unique(s.chain_ids):  # one colour per chain's carbons, read from the image
        mine = interior & np.isin(
            atom, np.flatnonzero((s.chain_ids == chain) & (s.elements == "C"))
        )
        if mine.sum() < 20:
            continue
        colours = np.unique(image[mine], axis=0)
        assert len(colours) == 1, f"chain {chain}'s carbons show {len(colours)} colours"
        carbon_colour[chain] = colours[0]
    assert len(carbon_colour) >= 2, carbon_colour
    values = np.array(list(carbon_colour.values()))
    gaps = np.abs(values[:, None] - values[None]).max(axis=2) + np.eye(len(values)) * 255
    assert gaps.min() >= 40, "two chains look alike"
    cpk = np.array([hex_rgb(c) for c in CPK.values()])
    assert np.abs(values[:, None] - cpk[None]).max(axis=2).min() >= 40, (
        "a chain colour looks like an element"
    )
    image, atom, interior = flat_render(gl, s, "chain-all")
    assert_drawn(
        image,
        atom,
        interior,
        {i: carbon_colour[c] for i, c in enumerate(s.chain_ids) if c in carbon_colour},
    )


def test_polymer_colours_protein_nucleic_ligand_water(gl, rb8, oky, reference_by_id):
    dna = rb8.positions[np.isin(rb8.residue_names, list(NUCLEOTIDES))].mean(axis=0)
    for s, clip in (
        (rb8, [[0.0, 0.0, -1.0, float(dna[2])]]),
        (oky, []),
    ):  # 1RB8 cut open at its DNA (view: -z)
        sizes = residue_sizes(s)
        image, atom, interior = flat_render(gl, s, "polymer", clip)
        kinds = {i: residue_kind(s, i, sizes) for i in range(s.n_atoms)}
        assert_drawn(image, atom, interior, {i: np.array(POLYMER[k]) for i, k in kinds.items()})
        seen = {kinds[int(i)] for i in np.unique(atom[interior])}
        assert seen >= ({"protein", "nucleic"} if s is rb8 else {"protein", "ligand", "water"}), (
            seen
        )
    from sasprobe.molecule.colors import scheme_colors

    aon = load_structure(
        reference_by_id["1aon"].path
    )  # its magnesium ions are buried: the colours, not the pixels
    ions = np.flatnonzero(aon.residue_names == "MG")
    assert ions.size == 7
    np.testing.assert_allclose(
        scheme_colors(aon, "polymer")[ions] * 255, np.tile(POLYMER["ion"], (7, 1)), atol=0.5
    )


def test_bfactor_and_sas_ramps_and_the_colour_bar(gl, rb8, reference_by_id):
    s = rb8
    # B-factors are the file's (columns 61-66), in file order: 1RB8 has no alternate locations
    text = gzip.decompress(reference_by_id["1rb8"].path.read_bytes()).decode().splitlines()
    file_b = [
        float(line[60:66])
        for line in text
        if line.startswith(("ATOM", "HETATM")) and line[17:20] != "HOH"
    ]
    np.testing.assert_allclose(s.b_factors, file_b)
    low, high = np.percentile(file_b, [2, 98])
    image, atom, interior = flat_render(gl, s, "bfactor")
    blue, white, red = (40, 80, 220), (255, 255, 255), (220, 40, 40)
    assert_drawn(
        image, atom, interior, dict(enumerate(linear_ramp(file_b, low, high, [blue, white, red])))
    )
    corner = image[
        -40:, -200:
    ]  # the colour bar, bottom right: blue at its left end, red at its right
    assert (
        np.abs(corner - blue).max(axis=2).min() <= 12
        and np.abs(corner - red).max(axis=2).min() <= 12
    )

    areas = shrake_rupley(UniformGrid(s.positions, s.expanded_radii(DEFAULT_PROBE_RADIUS))).areas
    stops = [(40, 30, 110), (40, 120, 160), (70, 190, 120), (250, 230, 40)]
    expected = linear_ramp(areas, 0.0, 40.0, stops)
    expected[areas < 0.5] = (70, 70, 70)
    image, atom, interior = flat_render(gl, s, "sas")
    assert_drawn(image, atom, interior, dict(enumerate(expected)))


def test_default_scheme_by_structure(crambin, reference_by_id):
    from sasprobe.molecule.colors import LARGE_STRUCTURE, default_scheme

    assert default_scheme(crambin) == "element"  # one chain
    assert (
        default_scheme(load_structure(reference_by_id["1oky"].path)) == "element"
    )  # one chain and ligands
    tii = load_structure(reference_by_id["1tii"].path)
    assert tii.n_atoms < LARGE_STRUCTURE and default_scheme(tii) == "chain"
    aon = load_structure(reference_by_id["1aon"].path)
    assert aon.n_atoms >= LARGE_STRUCTURE and default_scheme(aon) == "chain-all"
