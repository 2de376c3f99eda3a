"""Colours every renderer draws with (the desktop window and the browser page alike): the
atoms' colour schemes (`--color`, the window's C key, the scene's `color_scheme`, whose
names protocol/scene.py lists), the session's own colours and the Phong terms they are
lit with.

    element         CPK as Jmol has it (molecule/elements.py)
    chain           carbons in their chain's colour, every other element in its CPK colour
                    (PyMOL's util.cbc); chains in order of first appearance
    chain-all       every atom in its chain's colour (PyMOL's "by chain" without "elem C")
    polymer         protein, nucleic acid, ligand, water, ion (molecule/residues.py decides)
    residue         amino acids in RasMol's "amino" colours; nucleotides and others ours
    hydrophobicity  Kyte & Doolittle (1982) hydropathy: teal −4.5, white 0, orange +4.5;
                    atoms outside the 20 amino acids grey
    bfactor         B from blue (lowest) through white to red (highest) over the structure's
                    2nd to 98th percentile, with a colour bar
    sas             each atom's exposed SAS area (molecule/sas.py, the spheres the probe feels
                    at the scene's probe radius) from dark blue (0) to yellow (40 Å² or more),
                    buried atoms (< 0.5 Å², the accessibility threshold) dark grey; a colour bar

The default by structure (`default_scheme`): `element` for one polymer chain (protein or
nucleic acid); for several, `chain`, or `chain-all` from LARGE_STRUCTURE atoms up, where a
whole-molecule view shows atoms a few pixels wide and element colours on them are a
red-and-blue speckle that hides the chains (6ZU5's ribosome).

RasMol amino colours (RGB 0-255), from the RasMol colour-scheme documentation
(RasFrames, "Colors and Color Schemes", Carnegie Mellon's BiochemMols course pages):
ASP, GLU 230,10,10; CYS, MET 230,230,0; LYS, ARG 20,90,255; SER, THR 250,150,0; PHE, TYR
50,50,170; ASN, GLN 0,220,220; GLY 235,235,235; LEU, VAL, ILE 15,130,15; ALA 200,200,200;
TRP 180,90,180; HIS 130,130,210; PRO 220,150,130.

The chain palette is greedy farthest-point sampling in CIELAB (the idea of Glasbey, van der
Heijden, Toh and Gray, "Colour displays for categorical images", Color Res. Appl. 32, 2007):
each next colour is the candidate farthest from every colour taken so far, starting from
CPK's carbon, nitrogen, oxygen, sulphur and hydrogen, so no chain's carbons look like a
hetero atom. Candidates are an sRGB lattice restricted to mid lightness and some chroma.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from sasprobe.molecule import Structure
from sasprobe.molecule.elements import CPK_COLORS
from sasprobe.molecule.residues import (
    ION,
    KINDS,
    KYTE_DOOLITTLE_RANGE,
    LIGAND,
    NUCLEIC,
    PROTEIN,
    WATER,
    hydropathy,
    residue_kinds,
)
from sasprobe.molecule.sas import ACCESSIBLE_MIN_AREA


def _rgb(r: int, g: int, b: int) -> tuple[float, float, float]:
    return (r / 255.0, g / 255.0, b / 255.0)


POLYMER_COLORS = {  # indexed by molecule/residues.py's kind codes
    PROTEIN: _rgb(140, 170, 220),  # light steel blue
    NUCLEIC: _rgb(240, 150, 50),  # orange
    LIGAND: _rgb(80, 200, 80),  # green
    WATER: _rgb(255, 140, 140),  # pale red
    ION: _rgb(170, 80, 230),  # violet
}
RASMOL_AMINO = {
    **dict.fromkeys(("ASP", "GLU"), _rgb(230, 10, 10)),
    **dict.fromkeys(("CYS", "MET"), _rgb(230, 230, 0)),
    **dict.fromkeys(("LYS", "ARG"), _rgb(20, 90, 255)),
    **dict.fromkeys(("SER", "THR"), _rgb(250, 150, 0)),
    **dict.fromkeys(("PHE", "TYR"), _rgb(50, 50, 170)),
    **dict.fromkeys(("ASN", "GLN"), _rgb(0, 220, 220)),
    "GLY": _rgb(235, 235, 235),
    **dict.fromkeys(("LEU", "VAL", "ILE"), _rgb(15, 130, 15)),
    "ALA": _rgb(200, 200, 200),
    "TRP": _rgb(180, 90, 180),
    "HIS": _rgb(130, 130, 210),
    "PRO": _rgb(220, 150, 130),
}
NUCLEOTIDE_COLORS = {  # ours: purines warm, pyrimidines cool
    **dict.fromkeys(("A", "DA"), _rgb(230, 90, 80)),
    **dict.fromkeys(("G", "DG"), _rgb(240, 180, 60)),
    **dict.fromkeys(("C", "DC"), _rgb(80, 160, 230)),
    **dict.fromkeys(("U", "DU", "T", "DT"), _rgb(90, 200, 150)),
}
OTHER_RESIDUE = _rgb(190, 160, 110)  # tan: residues neither table names
NOT_AMINO_ACID = _rgb(150, 150, 150)  # hydrophobicity of everything else
BURIED = _rgb(70, 70, 70)  # sas: below the accessibility threshold
HYDROPATHY_STOPS = (_rgb(0, 150, 160), _rgb(255, 255, 255), _rgb(230, 120, 20))  # -4.5, 0, +4.5
BFACTOR_STOPS = (_rgb(40, 80, 220), _rgb(255, 255, 255), _rgb(220, 40, 40))
SAS_STOPS = (_rgb(40, 30, 110), _rgb(40, 120, 160), _rgb(70, 190, 120), _rgb(250, 230, 40))
SAS_BAR_MAX = 40.0  # Å²: the colour bar's top; more exposed atoms are yellow too

# The session's own colours (rgb 0..1), none of them a CPK colour.
BACKGROUND = (0.08, 0.09, 0.11)
HIGHLIGHT = (0.1, 1.0, 0.5)  # the touched atom, mixed 60 % into its colour: mint
PROBE_COLOR = (0.92, 0.95, 1.0)  # near white: the probe is the light source
CUBE_WIRE_COLOR = (0.55, 0.85, 1.0)
MARK_COLOR = (142 / 255, 68 / 255, 173 / 255)  # the marks' badges: violet
# The force arrow: below half the device's continuous rating, up to it, above it.
FORCE_COLORS = ((0.35, 0.95, 0.45), (1.0, 0.85, 0.2), (1.0, 0.3, 0.25))


def force_color(force: float, continuous: float) -> tuple[float, float, float]:
    if force <= 0.5 * continuous:
        return FORCE_COLORS[0]
    return FORCE_COLORS[1] if force <= continuous else FORCE_COLORS[2]


@dataclass(frozen=True)
class Lit:
    """Phong terms an atom's colour is lit with: ambient, a directional light and the probe's
    point light, 1 / (c + l d + q d²) windowed to 0 at `probe_range` Å."""

    ambient: float = 0.28
    directional: float = 0.75
    probe: float = 1.0
    probe_attenuation: tuple[float, float, float] = (1.0, 0.0, 0.02)  # half at 7 Å
    probe_range: float = 20.0  # Å
    shininess: float = 40.0
    specular: float = 0.25


LIT = Lit()


def ramp(values: np.ndarray, low: float, high: float, stops) -> np.ndarray:
    """(N, 3) float32: values mapped linearly from [low, high] onto evenly spaced colour stops."""
    stops = np.asarray(stops, dtype=np.float64)
    t = np.clip((np.asarray(values, dtype=np.float64) - low) / max(high - low, 1e-12), 0.0, 1.0)
    x = t * (len(stops) - 1)
    i = np.minimum(x.astype(np.int64), len(stops) - 2)
    f = (x - i)[:, None]
    return (stops[i] * (1.0 - f) + stops[i + 1] * f).astype(np.float32)


@dataclass(frozen=True)
class ColorBar:
    """What a colour bar shows: a title, the values at its ends and the ramp between."""

    title: str
    low: float
    high: float
    stops: tuple


# --------------------------------------------------------------- chain palette
def _srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """CIELAB (D65) of sRGB colours in 0..1, (N, 3)."""
    c = np.asarray(rgb, dtype=np.float64)
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = linear @ m.T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.column_stack(
        (116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2]))
    )


@lru_cache(maxsize=8)
def chain_palette(n: int) -> np.ndarray:
    """n distinct colours (float32 rgb), far from the CPK colours of C, N, O, S and H."""
    levels = np.linspace(0.0, 1.0, 16)
    candidates = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), axis=-1).reshape(
        -1, 3
    )
    lab = _srgb_to_lab(candidates)
    chroma = np.hypot(lab[:, 1], lab[:, 2])
    keep = (lab[:, 0] > 50) & (lab[:, 0] < 85) & (chroma > 30) & (chroma < 70)  # no garish corners
    candidates, lab = candidates[keep], lab[keep]
    taken = _srgb_to_lab(np.array([CPK_COLORS[e] for e in ("C", "N", "O", "S", "H")]))
    nearest = np.min(np.linalg.norm(lab[:, None, :] - taken[None, :, :], axis=2), axis=1)
    out = np.empty((n, 3), dtype=np.float32)
    for k in range(n):
        best = int(np.argmax(nearest))
        out[k] = candidates[best]
        nearest = np.minimum(nearest, np.linalg.norm(lab - lab[best], axis=1))
    return out


# --------------------------------------------------------------- schemes
def polymer_chains(structure: Structure) -> int:
    """How many chains hold protein or nucleic-acid residues."""
    kinds = residue_kinds(structure)
    return int(np.unique(structure.chain_ids[(kinds == PROTEIN) | (kinds == NUCLEIC)]).size)


LARGE_STRUCTURE = 20_000  # atoms


def default_scheme(structure: Structure) -> str:
    if polymer_chains(structure) <= 1:
        return "element"
    return "chain-all" if structure.n_atoms >= LARGE_STRUCTURE else "chain"


def chain_colors(structure: Structure) -> np.ndarray:
    """(n_atoms, 3): each atom's chain colour (the palette in order of first appearance)."""
    _, first, inverse = np.unique(structure.chain_ids, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first))  # rank of each chain by first appearance
    return chain_palette(max(len(first), 1))[order[inverse.reshape(-1)]]


def bfactor_bar(structure: Structure) -> ColorBar:
    b = structure.b_factors
    low, high = (float(v) for v in np.percentile(b, [2, 98])) if b.size else (0.0, 1.0)
    return ColorBar("B-factor (Å²)", low, high if high > low else low + 1.0, BFACTOR_STOPS)


SAS_BAR = ColorBar("SAS per atom (Å²)", 0.0, SAS_BAR_MAX, SAS_STOPS)


def scheme_colors(structure: Structure, scheme: str, areas: np.ndarray | None = None) -> np.ndarray:
    """(n_atoms, 3) float32 colours of a scheme; `areas` (per-atom SAS) for 'sas'."""
    if scheme == "element":
        return structure.colors.astype(np.float32)
    if scheme == "chain":
        out = structure.colors.astype(np.float32).copy()
        carbon = structure.elements == "C"
        out[carbon] = chain_colors(structure)[carbon]
        return out
    if scheme == "chain-all":
        return chain_colors(structure).astype(np.float32)
    if scheme == "polymer":
        table = np.array([POLYMER_COLORS[k] for k in range(len(KINDS))], dtype=np.float32)
        return table[residue_kinds(structure)]
    if scheme == "residue":
        unique, inverse = np.unique(structure.residue_names, return_inverse=True)
        table = np.array(
            [
                RASMOL_AMINO.get(str(r), NUCLEOTIDE_COLORS.get(str(r), OTHER_RESIDUE))
                for r in unique
            ],
            dtype=np.float32,
        ).reshape(-1, 3)
        return table[inverse.reshape(-1)]
    if scheme == "hydrophobicity":
        h = hydropathy(structure)
        out = ramp(np.nan_to_num(h), *KYTE_DOOLITTLE_RANGE, HYDROPATHY_STOPS)
        out[np.isnan(h)] = NOT_AMINO_ACID
        return out
    if scheme == "bfactor":
        bar = bfactor_bar(structure)
        return ramp(structure.b_factors, bar.low, bar.high, bar.stops)
    if scheme == "sas":
        if areas is None:
            raise ValueError("the sas scheme needs the atoms' SAS areas")
        out = ramp(areas, SAS_BAR.low, SAS_BAR.high, SAS_BAR.stops)
        out[np.asarray(areas) < ACCESSIBLE_MIN_AREA] = BURIED
        return out
    raise ValueError(f"unknown colour scheme {scheme!r}")


def color_bar(structure: Structure, scheme: str) -> ColorBar | None:
    """The colour bar a scheme shows, or None."""
    if scheme == "bfactor":
        return bfactor_bar(structure)
    if scheme == "sas":
        return SAS_BAR
    return None


class AtomAreas:
    """Per-atom SAS areas of the scene's grid (shrake_rupley), computed once per grid: at
    once, or on a background thread so a window keeps drawing (numpy's products release
    the GIL) while a large structure's areas are worked out."""

    def __init__(self):
        self._grid = None
        self._areas: np.ndarray | None = None
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def get(self, grid, wait: bool = True) -> np.ndarray | None:
        from sasprobe.molecule.sas import shrake_rupley

        with self._lock:
            if grid is not self._grid:
                self._grid, self._areas, self._thread = grid, None, None
            if self._areas is not None:
                return self._areas
            if wait:
                self._areas = shrake_rupley(grid).areas
                return self._areas
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._compute, args=(grid,), daemon=True, name="sas-areas"
                )
                self._thread.start()
            return None

    @property
    def pending(self) -> bool:
        return self._thread is not None and self._areas is None

    def _compute(self, grid) -> None:
        from sasprobe.molecule.sas import shrake_rupley

        areas = shrake_rupley(grid).areas
        with self._lock:
            if grid is self._grid:
                self._areas = areas
