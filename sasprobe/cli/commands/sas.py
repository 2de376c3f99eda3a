"""`sasprobe sas [FILE]`: solvent accessible surface area of the felt spheres: the total
and per chain on the terminal, per atom as CSV or JSON, or per residue."""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time

from sasprobe.cli.argtypes import probe_radius
from sasprobe.cli.structure_args import MOLECULE_HELP, add_fetch_options, resolve_molecule

HELP = (
    "solvent accessible surface area (Shrake-Rupley): total and per chain, per atom (--csv, "
    "--json) or --per-residue"
)
RESIDUE_COLUMNS = ("chain", "number", "icode", "residue", "atoms", "area", "accessible_atoms")


def _points(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if not 16 <= value <= 65536:
        raise argparse.ArgumentTypeError(
            f"{value} test points per atom is out of range (16..65536)"
        )
    return value


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS
    from sasprobe.molecule.sas import DEFAULT_POINTS, REFINE_POINTS

    p = sub.add_parser("sas", help=HELP)
    p.add_argument("file", nargs="?", help=MOLECULE_HELP)
    out = p.add_mutually_exclusive_group()
    out.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object with per-atom (or per-residue) columns",
    )
    out.add_argument(
        "--csv",
        action="store_true",
        help="print CSV: one row per atom, or per residue with --per-residue",
    )
    p.add_argument(
        "--per-residue",
        action="store_true",
        help="one row per residue: chain, number, insertion code, name, atoms, area (Å²), "
        "accessible atoms",
    )
    p.add_argument(
        "--probe-radius",
        type=probe_radius,
        default=DEFAULT_PROBE_RADIUS,
        help=f"Å (default {DEFAULT_PROBE_RADIUS:g})",
    )
    p.add_argument(
        "--points",
        type=_points,
        default=DEFAULT_POINTS,
        help=f"test points per atom (default {DEFAULT_POINTS})",
    )
    p.add_argument(
        "--refine-points",
        type=_points,
        default=REFINE_POINTS,
        help=f"points for atoms with a small exposed area (default {REFINE_POINTS})",
    )
    p.add_argument("--keep-water", action="store_true", help="keep water molecules")
    add_fetch_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from sasprobe.molecule import UniformGrid, load_structure_or_default
    from sasprobe.molecule.residues import per_residue_sums
    from sasprobe.molecule.sas import ACCESSIBLE_MIN_AREA, shrake_rupley

    structure = load_structure_or_default(
        resolve_molecule(args, args.file), keep_water=args.keep_water
    )
    t0 = time.perf_counter()
    grid = UniformGrid(structure.positions, structure.expanded_radii(args.probe_radius))
    result = shrake_rupley(grid, args.points, args.refine_points)
    seconds = time.perf_counter() - t0
    accessible = result.accessible
    residues = None
    if args.per_residue:
        residues = [
            {**row, "area": round(row["area"], 4), "accessible_atoms": int(row["accessible_atoms"])}
            for row in per_residue_sums(structure, area=result.areas, accessible_atoms=accessible)
        ]
    if args.csv:
        _write_csv(structure, result, residues)
        return 0
    if args.json:
        summary = {
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
        }
        if residues is not None:
            summary["residues"] = {key: [row[key] for row in residues] for key in RESIDUE_COLUMNS}
        else:
            summary["atoms"] = {
                "chain": structure.chain_ids.tolist(),
                "residue": structure.residue_names.tolist(),
                "number": structure.residue_numbers.tolist(),
                "name": structure.atom_names.tolist(),
                "element": structure.elements.tolist(),
                "vdw_radius": structure.vdw_radii.tolist(),
                "expanded_radius": result.expanded_radii.tolist(),
                "area": np.round(result.areas, 4).tolist(),
                "accessible": accessible.tolist(),
            }
        print(json.dumps(summary))
        return 0
    print(
        f"{structure.name}: SAS {result.total:.1f} Å² (probe {args.probe_radius} Å, Shrake-Rupley "
        f"{result.n_points} points, {result.n_refined} atoms refined at {result.refine_points})"
    )
    print(
        f"  accessible atoms (≥ {ACCESSIBLE_MIN_AREA} Å²): {int(accessible.sum())} of "
        f"{structure.n_atoms}"
    )
    if residues is not None:
        print(
            f"  {'chain':>5} {'residue':>9} {'name':<5} {'atoms':>5} {'area Å²':>9} "
            f"{'accessible':>10}"
        )
        for row in residues:
            print(
                f"  {row['chain']:>5} {str(row['number']) + row['icode']:>9} {row['residue']:<5} "
                f"{row['atoms']:>5} {row['area']:9.1f} {row['accessible_atoms']:>10}"
            )
    else:
        for chain in np.unique(structure.chain_ids):
            mask = structure.chain_ids == chain
            print(
                f"  chain {chain:>4}: {result.areas[mask].sum():10.1f} Å²  "
                f"({int(accessible[mask].sum())} accessible atoms)"
            )
    print(f"  time {seconds:.2f} s (grid + area)")
    return 0


def _write_csv(structure, result, residues: list[dict] | None) -> None:
    writer = csv.writer(sys.stdout, lineterminator="\n")
    if residues is not None:
        writer.writerow(RESIDUE_COLUMNS)
        writer.writerows([row[key] for key in RESIDUE_COLUMNS] for row in residues)
        return
    writer.writerow(
        ("chain", "number", "icode", "residue", "atom", "element", "area", "accessible")
    )
    s = structure
    for i in range(s.n_atoms):
        writer.writerow(
            (
                s.chain_ids[i],
                int(s.residue_numbers[i]),
                s.insertion_codes[i],
                s.residue_names[i],
                s.atom_names[i],
                s.elements[i],
                round(float(result.areas[i]), 4),
                bool(result.accessible[i]),
            )
        )
