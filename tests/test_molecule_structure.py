"""Structure loading: shared entries against gemmi's own counts, and the filtering rules."""

from __future__ import annotations

import gzip

import gemmi
import numpy as np
import pytest
from sasprobe.molecule import StructureError, load_default, load_structure, parse_structure
from sasprobe.molecule.elements import BONDI_RADII, FALLBACK_RADIUS

# Entries whose files hold one model, no waters and no alternate locations: the
# loader must return exactly the manifest's atom count.
UNFILTERED = {"1crn", "1rb8", "3sn6", "1aon", "6zu5"}


def independent_count(path, keep_water=False) -> int:
    """Atom count by the rules, made with gemmi's own API (not the loader's code path)."""
    st = gemmi.read_structure(str(path))
    model = st[0]
    n = 0
    for chain in model:
        residues = list(chain)
        # group residues sharing a position (microheterogeneity) like the rules do
        groups: dict[tuple, list] = {}
        for res in residues:
            if not keep_water and res.is_water():
                continue
            groups.setdefault((res.seqid.num, res.seqid.icode), []).append(res)
        for group in groups.values():
            atoms = [a for res in group for a in res]
            letters: dict[str, float] = {}
            for a in atoms:
                if a.altloc != "\0":
                    letters[a.altloc] = max(letters.get(a.altloc, -1.0), a.occ)
            best = None
            if letters:
                top = max(letters.values())
                best = next(k for k in letters if letters[k] == top)  # dict keeps first-seen order
            n += sum(1 for a in atoms if a.altloc in ("\0", best))
    return n


def test_every_shared_structure_loads_with_the_expected_count(reference_entries):
    for entry in reference_entries:
        s = load_structure(entry.path)
        assert s.n_atoms == independent_count(entry.path), entry.id
        if entry.id in UNFILTERED:
            assert s.n_atoms == entry.atoms, entry.id
        assert s.positions.shape == (s.n_atoms, 3) and s.positions.dtype == np.float64
        assert np.all(np.isfinite(s.positions))
        assert s.vdw_radii.shape == (s.n_atoms,) and np.all(
            (s.vdw_radii > 1.0) & (s.vdw_radii < 3.0)
        )
        assert s.colors.shape == (s.n_atoms, 3) and np.all((s.colors >= 0) & (s.colors <= 1))
        for column in (
            s.elements,
            s.chain_ids,
            s.residue_names,
            s.residue_numbers,
            s.atom_names,
            s.is_hetero,
        ):
            assert column.shape == (s.n_atoms,)
        assert len(s.sha256) == 64


def test_waters_removed_unless_kept(reference_by_id):
    entry = reference_by_id["1tii"]  # 215 waters in the file
    dry = load_structure(entry.path)
    wet = load_structure(entry.path, keep_water=True)
    assert not np.any(np.isin(dry.residue_names, ["HOH", "WAT", "DOD"]))
    assert wet.n_atoms - dry.n_atoms == 215
    assert wet.n_atoms == independent_count(entry.path, keep_water=True)


def test_ligands_and_ions_kept(reference_by_id):
    s = load_structure(reference_by_id["1jb0"].path)  # chlorophylls with Mg, Fe-S clusters
    assert {"Fe", "Mg"} <= set(s.elements.tolist())
    assert s.is_hetero.sum() > 6000
    assert "CLA" in set(s.residue_names[s.is_hetero].tolist())


def _pdb_line(serial, name, alt, resn, chain, resi, xyz, occ, element):
    return (
        f"ATOM  {serial:5d} {name:<4}{alt:1}{resn:>3} {chain:1}{resi:4d}    "
        f"{xyz[0]:8.3f}{xyz[1]:8.3f}{xyz[2]:8.3f}{occ:6.2f}{10.0:6.2f}          {element:>2}\n"
    )


def test_altloc_keeps_highest_occupancy_then_first():
    lines = [
        _pdb_line(1, "N", "", "SER", "A", 1, (0, 0, 0), 1.0, "N"),
        _pdb_line(2, "CA", "", "SER", "A", 1, (1.4, 0, 0), 1.0, "C"),
        _pdb_line(3, "OG", "A", "SER", "A", 1, (2, 1, 0), 0.3, "O"),
        _pdb_line(4, "OG", "B", "SER", "A", 1, (2, -1, 0), 0.7, "O"),
        _pdb_line(5, "N", "", "GLY", "A", 2, (3.8, 0, 0), 1.0, "N"),
        _pdb_line(6, "CA", "A", "GLY", "A", 2, (4.5, 1, 0), 0.5, "C"),
        _pdb_line(7, "CA", "B", "GLY", "A", 2, (4.5, -1, 0), 0.5, "C"),
    ]
    s = parse_structure("".join(lines).encode(), name="t", source="t.pdb")
    assert s.n_atoms == 5
    og = s.positions[s.atom_names == "OG"]
    np.testing.assert_allclose(og, [[2, -1, 0]])  # B: 0.7 beats 0.3
    ca2 = s.positions[(s.atom_names == "CA") & (s.residue_numbers == 2)]
    np.testing.assert_allclose(ca2, [[4.5, 1, 0]])  # tie: the first (A)


def test_first_model_only_and_hydrogens_kept():
    m1 = _pdb_line(1, "N", "", "GLY", "A", 1, (0, 0, 0), 1, "N") + _pdb_line(
        2, "H", "", "GLY", "A", 1, (0, 1, 0), 1, "H"
    )
    m2 = _pdb_line(1, "N", "", "GLY", "A", 1, (5, 5, 5), 1, "N")
    text = f"MODEL        1\n{m1}ENDMDL\nMODEL        2\n{m2}ENDMDL\nEND\n"
    s = parse_structure(text.encode(), name="t", source="t.pdb")
    assert s.n_atoms == 2
    assert "H" in s.elements.tolist()
    assert s.vdw_radii[s.elements == "H"][0] == BONDI_RADII["H"]
    np.testing.assert_allclose(s.positions[0], [0, 0, 0])


def test_mmcif_and_gzip_give_the_same_atoms_as_pdb(reference_by_id, tmp_path):
    entry = reference_by_id["1crn"]
    from_gz = load_structure(entry.path)
    plain = tmp_path / "1crn.pdb"
    plain.write_bytes(gzip.decompress(entry.path.read_bytes()))
    cif = tmp_path / "1crn.cif"
    gemmi.read_structure(str(plain)).make_mmcif_document().write_file(str(cif))
    for other in (load_structure(plain), load_structure(cif)):
        assert other.n_atoms == from_gz.n_atoms
        np.testing.assert_allclose(other.positions, from_gz.positions)
        assert other.atom_names.tolist() == from_gz.atom_names.tolist()


def test_unknown_element_gets_fallback_radius_and_one_warning():
    lines = [_pdb_line(i + 1, "QQ", "", "UNK", "A", 1, (i * 3.0, 0, 0), 1.0, "") for i in range(4)]
    s = parse_structure("".join(lines).encode(), name="t", source="odd.pdb")
    assert set(s.elements.tolist()) == {"X"}
    assert np.all(s.vdw_radii == FALLBACK_RADIUS)
    assert len(s.warnings) == 1 and "odd.pdb" in s.warnings[0] and "4 atom" in s.warnings[0]


def test_default_is_crambin():
    s = load_default()
    assert s.name == "1crn" and s.n_atoms == 327 and s.n_residues == 46 and s.n_chains == 1
    assert s.source.startswith("embedded:")


def test_backbone_trace_segments(reference_by_id):
    crambin = load_default()
    assert len(crambin.backbone) == 1 and len(crambin.backbone[0]) == 46
    assert set(crambin.atom_names[crambin.backbone[0]].tolist()) == {"CA"}
    dna = load_structure(reference_by_id["1rb8"].path)  # protein chains + DNA
    p_segments = [seg for seg in dna.backbone if dna.atom_names[seg[0]] == "P"]
    assert p_segments, "nucleic-acid P trace missing"
    for seg, chain in zip(dna.backbone, dna.backbone_chains):
        assert set(dna.chain_ids[seg].tolist()) == {chain}
        steps = np.linalg.norm(np.diff(dna.positions[seg], axis=0), axis=1)
        limit = 4.2 if dna.atom_names[seg[0]] == "CA" else 8.0
        assert np.all(steps <= limit)


def test_backbone_splits_at_a_chain_break():
    xyz = [(i * 3.8, 0, 0) for i in range(3)] + [(20 + i * 3.8, 0, 0) for i in range(3)]
    lines = [_pdb_line(i + 1, "CA", "", "ALA", "A", i + 1, p, 1.0, "C") for i, p in enumerate(xyz)]
    s = parse_structure("".join(lines).encode(), name="t", source="t.pdb")
    assert [len(seg) for seg in s.backbone] == [3, 3]


@pytest.mark.parametrize(
    "axis, field, problem",
    [
        (0, "  abc.de", "line 2: the x coordinate 'abc.de' is not a number"),
        (2, "        ", "line 2: the z coordinate is blank"),
        (1, " 1.2.3  ", "line 2: the y coordinate '1.2.3' is not a number"),
    ],
)
def test_a_coordinate_that_is_not_a_number_is_refused(axis, field, problem):
    """gemmi reads such a field as 0.0 Å: the atom would sit at the origin, unsaid."""
    line = _pdb_line(2, "CA", "", "GLY", "A", 1, (1.5, 2.5, 3.5), 1.0, "C")
    start = 30 + 8 * axis
    line = line[:start] + field + line[start + 8 :]
    text = _pdb_line(1, "N", "", "GLY", "A", 1, (0, 0, 0), 1.0, "N") + line + "END\n"
    with pytest.raises(StructureError) as caught:
        parse_structure(text.encode(), name="t", source="t.pdb")
    assert str(caught.value) == f"t.pdb: {problem}"
