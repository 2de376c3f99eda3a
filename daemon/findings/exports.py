"""The findings as files other programs open: the structure, the path as pseudo-atoms
(PDB and mmCIF, written by gemmi), and PyMOL and ChimeraX scripts that show them.

The path file has chain P, one HETATM `PTH` pseudo-atom (element X) per path point in
order, its B-factor the passage radius there (Å, OPEN_RADIUS_A where open), and chain M,
one `MRK` pseudo-atom per mark numbered by the mark. Both scripts `cd` into the folder
they were written in (PyMOL resolves file names against its working directory), open the
structure and the path, colour the path by B-factor (red where it is as tight as the
probe, blue where open), label the marks, select the touched residues (`touched`) and
show the atoms that form the bottleneck.

Command syntax from the programs' own documentation: ChimeraX's user guide (atom
specifiers `#model/chain:residue@atom`, `label ... atoms text`, `name`, `size ...
atomRadius`) and its gallery sample bfactor.cxc (`color bfactor ... palette A:B:C range
lo,hi`), www.cgl.ucsf.edu/chimerax/docs/user/commands/; PyMOL's `spectrum`, `pseudoatom`,
`label` and `select`. PyMOL runs the script in the tests; ChimeraX is not installed here.
"""

from __future__ import annotations

import gzip
import re
from dataclasses import dataclass
from pathlib import Path

import gemmi
import numpy as np
from sasprobe.molecule.clearance import OPEN_RADIUS_A

PATH_CHAIN, MARK_CHAIN = "P", "M"


def write_structure(data: bytes, folder: Path) -> Path:
    """The recording's structure file, uncompressed, as structure.pdb or structure.cif."""
    if data[:2] == b"\x1f\x8b":
        data = gzip.decompress(data)
    is_cif = re.search(rb"^data_", data[:65536], re.M) is not None
    out = folder / ("structure.cif" if is_cif else "structure.pdb")
    out.write_bytes(data)
    return out


def path_structure(points: np.ndarray, b_factors: np.ndarray, marks: list[dict]) -> gemmi.Structure:
    st = gemmi.Structure()
    st.name = "sasprobe_path"
    model = gemmi.Model(1)
    for chain_name, resname, atom_name, rows in (
        (
            PATH_CHAIN,
            "PTH",
            "PT",
            [(k + 1, p, b) for k, (p, b) in enumerate(zip(points, b_factors))],
        ),
        (MARK_CHAIN, "MRK", "MK", [(m["id"], m["position_A"], 0.0) for m in marks]),
    ):
        chain = gemmi.Chain(chain_name)
        for number, position, b in rows:
            residue = gemmi.Residue()
            residue.name = resname
            residue.seqid = gemmi.SeqId(int(number), " ")
            residue.het_flag = "H"
            atom = gemmi.Atom()
            atom.name = atom_name
            atom.element = gemmi.Element("X")
            atom.pos = gemmi.Position(*map(float, position))
            atom.occ = 1.0
            atom.b_iso = float(b)
            residue.add_atom(atom)
            chain.add_residue(residue)
        if len(chain):
            model.add_chain(chain)
    st.add_model(model)
    st.setup_entities()
    return st


def write_path(folder: Path, points: np.ndarray, passage_A: np.ndarray, marks: list[dict]) -> dict:
    st = path_structure(points, np.minimum(passage_A, OPEN_RADIUS_A), marks)
    pdb, cif = folder / "path.pdb", folder / "path.cif"
    st.write_pdb(str(pdb))
    st.make_mmcif_document().write_file(str(cif))
    return {"path_pdb": pdb.name, "path_cif": cif.name}


def _grouped(residues: list[dict]) -> dict[str, list[str]]:
    by_chain: dict[str, list[str]] = {}
    for r in residues:
        by_chain.setdefault(r["chain"].strip(), []).append(f"{r['number']}{r['icode'].strip()}")
    return by_chain


@dataclass(frozen=True)
class ViewerScene:
    """What the PyMOL and ChimeraX scripts show, from the folder they are written in."""

    folder: Path
    structure_file: str
    probe_radius_A: float
    residues: list[dict]  # the touched residues
    marks: list[dict]
    bottleneck: dict | None
    title: str


def _quoted(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', "'") + '"'


def pymol_script(scene: ViewerScene) -> str:
    folder, probe_radius_A, marks = scene.folder, scene.probe_radius_A, scene.marks
    residues, bottleneck = scene.residues, scene.bottleneck
    lines = [
        f"# {scene.title}",
        "# written by sasprobe replay --findings (open it with: pymol session.pml)",
        f"cd {folder.resolve()}",
        f"load {scene.structure_file}, structure",
        "load path.pdb, path",
        "hide everything, path",
        f"show spheres, path and chain {PATH_CHAIN}",
        f"set sphere_scale, 0.25, path and chain {PATH_CHAIN}",
        f"spectrum b, red_white_blue, path and chain {PATH_CHAIN}, "
        f"minimum={probe_radius_A:g}, maximum={OPEN_RADIUS_A:g}",
    ]
    if marks:
        lines += [
            f"show spheres, path and chain {MARK_CHAIN}",
            f"set sphere_scale, 0.6, path and chain {MARK_CHAIN}",
            f"color magenta, path and chain {MARK_CHAIN}",
        ]
        lines += [
            f"label path and chain {MARK_CHAIN} and resi {m['id']}, "
            f"{_quoted(str(m['id']) + ': ' + m['label'])}"
            for m in marks
        ]
    if residues:
        terms = [
            f"({'chain ' + c + ' and ' if c else ''}resi {'+'.join(nums)})"
            for c, nums in _grouped(residues).items()
        ]
        lines += [f"select touched, structure and ({' or '.join(terms)})", "show sticks, touched"]
    if bottleneck is not None:
        terms = [
            f"({'chain ' + a['chain'].strip() + ' and ' if a['chain'].strip() else ''}resi "
            f"{a['number']}{a['icode'].strip()} and name {a['atom']})"
            for a in bottleneck["atoms"]
        ]
        c = bottleneck["center_A"]
        label = _quoted(f"bottleneck {bottleneck['radius_A']:.2f} A")
        lines += [
            f"select bottleneck, structure and ({' or '.join(terms)})",
            "show spheres, bottleneck",
            f"pseudoatom bottleneck_centre, pos=[{c[0]:.3f}, "
            f"{c[1]:.3f}, {c[2]:.3f}], label={label}",
        ]
    lines += ["deselect", "orient path"]
    return "\n".join(lines) + "\n"


def chimerax_script(scene: ViewerScene) -> str:
    folder, probe_radius_A, marks = scene.folder, scene.probe_radius_A, scene.marks
    residues, bottleneck = scene.residues, scene.bottleneck
    lines = [
        f"# {scene.title}",
        "# written by sasprobe replay --findings (open it with: chimerax session.cxc)",
        f"cd {_quoted(str(folder.resolve()))}",
        f"open {scene.structure_file}",
        "open path.pdb",
        "show #2 atoms",
        "style #2 sphere",
        f"size #2/{PATH_CHAIN} atomRadius 0.25",
        f"color bfactor #2/{PATH_CHAIN} palette red:white:blue range "
        f"{probe_radius_A:g},{OPEN_RADIUS_A:g}",
    ]
    if marks:
        lines += [f"size #2/{MARK_CHAIN} atomRadius 0.6", f"color #2/{MARK_CHAIN} magenta"]
        lines += [
            f"label #2/{MARK_CHAIN}:{m['id']} atoms text "
            f"{_quoted(str(m['id']) + ': ' + m['label'])}"
            for m in marks
        ]
    if residues:
        spec = " ".join(
            f"#1{'/' + c if c else ''}:{','.join(nums)}" for c, nums in _grouped(residues).items()
        )
        lines += [f"name touched {spec}", "show touched atoms", "style touched stick"]
    if bottleneck is not None:
        spec = " ".join(
            f"#1{'/' + a['chain'].strip() if a['chain'].strip() else ''}:"
            f"{a['number']}{a['icode'].strip()}@{a['atom']}"
            for a in bottleneck["atoms"]
        )
        lines += [f"name bottleneck {spec}", "show bottleneck atoms", "style bottleneck sphere"]
    lines += ["view #2"]
    return "\n".join(lines) + "\n"
