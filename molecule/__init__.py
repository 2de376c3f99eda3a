"""Structures, radii and colours, the uniform grid and the backbone trace."""

from sasprobe.molecule.grid import UniformGrid
from sasprobe.molecule.structure import (
    DEFAULT_PROBE_RADIUS,
    Structure,
    StructureError,
    load_default,
    load_structure,
    load_structure_or_default,
    parse_structure,
)

__all__ = [
    "DEFAULT_PROBE_RADIUS",
    "Structure",
    "StructureError",
    "UniformGrid",
    "load_default",
    "load_structure",
    "load_structure_or_default",
    "parse_structure",
]
