"""Per-element van der Waals radii and CPK colours.

Radii: A. Bondi, "van der Waals Volumes and Radii", J. Phys. Chem. 68, 441 (1964).
Elements Bondi does not list (Fe, Ca, Mn, Co, ...) and atoms whose element cannot be
determined get FALLBACK_RADIUS, 1.80 Å: the radius of P and S, inside the 1.4-2.2 Å
range of the table, so an unknown atom neither vanishes nor swallows its neighbours.

Colours: the CPK scheme as Jmol defines it (RGB 0..1); unknown elements are deep pink,
Jmol's own fallback, so they stand out.
"""

from __future__ import annotations

import numpy as np

BONDI_RADII: dict[str, float] = {
    "H": 1.20, "He": 1.40, "Li": 1.82, "C": 1.70, "N": 1.55, "O": 1.52, "F": 1.47,
    "Ne": 1.54, "Na": 2.27, "Mg": 1.73, "Si": 2.10, "P": 1.80, "S": 1.80, "Cl": 1.75,
    "Ar": 1.88, "K": 2.75, "Ni": 1.63, "Cu": 1.40, "Zn": 1.39, "Ga": 1.87, "As": 1.85,
    "Se": 1.90, "Br": 1.85, "Kr": 2.02, "Pd": 1.63, "Ag": 1.72, "Cd": 1.58, "In": 1.93,
    "Sn": 2.17, "Te": 2.06, "I": 1.98, "Xe": 2.16, "Pt": 1.72, "Au": 1.66, "Hg": 1.55,
    "Tl": 1.96, "Pb": 2.02, "U": 1.86,
}  # fmt: skip

FALLBACK_RADIUS = 1.80
# Deuterium is hydrogen for the surface.
_ALIASES = {"D": "H"}

_JMOL_HEX: dict[str, str] = {
    "H": "FFFFFF", "C": "909090", "N": "3050F8", "O": "FF0D0D", "F": "90E050",
    "Na": "AB5CF2", "Mg": "8AFF00", "P": "FF8000", "S": "FFFF30", "Cl": "1FF01F",
    "K": "8F40D4", "Ca": "3DFF00", "Mn": "9C7AC7", "Fe": "E06633", "Co": "F090A0",
    "Ni": "50D050", "Cu": "C88033", "Zn": "7D80B0", "Se": "FFA100", "Br": "A62929",
    "I": "940094", "Cd": "FFD98F", "Hg": "B8B8D0", "Pt": "D0D0E0", "Au": "FFD123",
}  # fmt: skip
FALLBACK_COLOR_HEX = "FF1493"


def _hex_to_rgb(code: str) -> tuple[float, float, float]:
    return tuple(int(code[i : i + 2], 16) / 255.0 for i in (0, 2, 4))  # type: ignore[return-value]


CPK_COLORS: dict[str, tuple[float, float, float]] = {
    k: _hex_to_rgb(v) for k, v in _JMOL_HEX.items()
}
FALLBACK_COLOR = _hex_to_rgb(FALLBACK_COLOR_HEX)


def vdw_radius(element: str) -> float:
    """Bondi radius of an element symbol (case as in the periodic table), or the fallback."""
    return BONDI_RADII.get(_ALIASES.get(element, element), FALLBACK_RADIUS)


def has_bondi_radius(element: str) -> bool:
    return _ALIASES.get(element, element) in BONDI_RADII


def radii_for(elements: np.ndarray) -> np.ndarray:
    """Vectorised lookup over an array of element symbols (float64)."""
    unique, inverse = np.unique(elements, return_inverse=True)
    table = np.array([vdw_radius(str(e)) for e in unique], dtype=np.float64)
    return table[inverse.reshape(-1)]


def colors_for(elements: np.ndarray) -> np.ndarray:
    """CPK colours (N x 3 float32, 0..1) for an array of element symbols."""
    unique, inverse = np.unique(elements, return_inverse=True)
    table = np.array(
        [CPK_COLORS.get(_ALIASES.get(str(e), str(e)), FALLBACK_COLOR) for e in unique],
        dtype=np.float32,
    ).reshape(-1, 3)
    return table[inverse.reshape(-1)]
