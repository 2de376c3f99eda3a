"""`sasprobe sas [FILE]`: per-atom solvent accessible surface area of the felt spheres."""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid, load_structure_or_default
from sasprobe.units import probe_radius


def _points(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if not 16 <= value <= 65536:
        raise argparse.ArgumentTypeError(f"{value} test points per atom is out of range (16..65536)")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.molecule.sas import DEFAULT_POINTS, REFINE_POINTS

    p = sub.add_parser("sas", help="per-atom solvent accessible surface area (Shrake-Rupley)")
    p.add_argument("file", nargs="?", help="PDB or mmCIF file, optionally .gz (default: embedded 1CRN)")
    p.add_argument("--json", action="store_true", help="print one JSON object with per-atom columns")
    p.add_argument("--probe-radius", type=probe_radius, default=DEFAULT_PROBE_RADIUS, help=f"Å (default {DEFAULT_PROBE_RADIUS:g})")
    p.add_argument("--points", type=_points, default=DEFAULT_POINTS, help=f"test points per atom (default {DEFAULT_POINTS})")
    p.add_argument("--refine-points", type=_points, default=REFINE_POINTS,
                   help=f"points for atoms with a small exposed area (default {REFINE_POINTS})")
    p.add_argument("--keep-water", action="store_true", help="keep water molecules")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.molecule.sas import ACCESSIBLE_MIN_AREA, shrake_rupley

    structure = load_structure_or_default(args.file, keep_water=args.keep_water)
    t0 = time.perf_counter()
    grid = UniformGrid(structure.positions, structure.expanded_radii(args.probe_radius))
    result = shrake_rupley(grid, args.points, args.refine_points)
    seconds = time.perf_counter() - t0
    accessible = result.accessible
    if args.json:
        print(json.dumps({
            "name": structure.name,
            "source": structure.source,
            "method": "shrake-rupley",
            "probe_radius": args.probe_radius,
            "points": result.n_points,
            "refine_points": result.refine_points,
            "n_refined": result.n_refined,
            "accessible_min_area": ACCESSIBLE_MIN_AREA,
            "n_atoms": structure.n_atoms,
            "n_accessible": int(accessible.sum()),
            "total_area": result.total,
            "seconds": seconds,
            "atoms": {
                "chain": structure.chain_ids.tolist(),
                "residue": structure.residue_names.tolist(),
                "number": structure.residue_numbers.tolist(),
                "name": structure.atom_names.tolist(),
                "element": structure.elements.tolist(),
                "vdw_radius": structure.vdw_radii.tolist(),
                "expanded_radius": result.expanded_radii.tolist(),
                "area": np.round(result.areas, 4).tolist(),
                "accessible": accessible.tolist(),
            },
        }))
        return 0
    print(f"{structure.name}: SAS {result.total:.1f} Å² (probe {args.probe_radius} Å, Shrake-Rupley "
          f"{result.n_points} points, {result.n_refined} atoms refined at {result.refine_points})")
    print(f"  accessible atoms (≥ {ACCESSIBLE_MIN_AREA} Å²): {int(accessible.sum())} of {structure.n_atoms}")
    for chain in np.unique(structure.chain_ids):
        mask = structure.chain_ids == chain
        print(f"  chain {chain:>4}: {result.areas[mask].sum():10.1f} Å²  ({int(accessible[mask].sum())} accessible atoms)")
    print(f"  time {seconds:.2f} s (grid + area)")
    return 0
