"""Structures, radii and colours, the solvent probe, the uniform grid and the backbone trace."""

from sasprobe.molecule.grid import UniformGrid
from sasprobe.molecule.loading import (
    load_default,
    load_structure,
    load_structure_or_default,
    parse_structure,
)
from sasprobe.molecule.probe import DEFAULT_PROBE_RADIUS, MAX_PROBE_RADIUS, check_probe_radius
from sasprobe.molecule.structure import Structure, StructureError

__all__ = [
    "DEFAULT_PROBE_RADIUS",
    "MAX_PROBE_RADIUS",
    "Structure",
    "StructureError",
    "UniformGrid",
    "check_probe_radius",
    "load_default",
    "load_structure",
    "load_structure_or_default",
    "parse_structure",
]
