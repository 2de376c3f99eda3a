"""Per-element surface materials for the path tracer: diffuse albedo (the CPK colour,
scaled so that white reflects 80 %) and a normalised Phong lobe for the lights' highlights;
metals and metal ions are shinier than the organic elements."""

from __future__ import annotations

import numpy as np

ALBEDO_SCALE = 0.8
ORGANIC = (0.04, 24.0)  # specular weight, Phong exponent
METAL = (0.35, 96.0)
METALS = frozenset(
    {"Na", "K", "Mg", "Ca", "Mn", "Fe", "Co", "Ni", "Cu", "Zn", "Cd", "Hg", "Pt", "Au", "Ag", "Pd"}
)
PROBE_MATERIAL = (0.85, 0.85, 0.9, 0.25, 48.0)  # rgb albedo, specular, exponent


def atom_materials(elements: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """(N, 8) float32 rows as the shader's Material struct: albedo rgb, specular weight,
    Phong exponent, 3 × padding."""
    elements = np.asarray(elements).astype(str)
    out = np.zeros((elements.shape[0], 8), dtype=np.float32)
    out[:, :3] = np.asarray(colors, dtype=np.float32) * ALBEDO_SCALE
    metal = np.isin(elements, list(METALS))
    out[:, 3] = np.where(metal, METAL[0], ORGANIC[0])
    out[:, 4] = np.where(metal, METAL[1], ORGANIC[1])
    return out
