"""`sasprobe info [FILE]`: what a structure holds and what its uniform grid costs."""

from __future__ import annotations

import argparse
import json
import time

from sasprobe.cli.argtypes import positive_float, probe_radius
from sasprobe.cli.structure_args import MOLECULE_HELP, add_fetch_options, resolve_molecule

HELP = "summarise a structure and its uniform grid"


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS

    p = sub.add_parser("info", help=HELP)
    p.add_argument("file", nargs="?", help=MOLECULE_HELP)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--probe-radius",
        type=probe_radius,
        default=DEFAULT_PROBE_RADIUS,
        help=f"Å (default {DEFAULT_PROBE_RADIUS:g})",
    )
    p.add_argument(
        "--cell-size",
        type=positive_float,
        default=None,
        help="grid cell edge in Å (default: largest expanded diameter)",
    )
    p.add_argument("--keep-water", action="store_true", help="keep water molecules")
    add_fetch_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.molecule import UniformGrid, load_structure_or_default
    from sasprobe.molecule.elements import FALLBACK_RADIUS, has_bondi_radius

    path = resolve_molecule(args, args.file)
    t0 = time.perf_counter()
    structure = load_structure_or_default(path, keep_water=args.keep_water)
    t1 = time.perf_counter()
    grid = UniformGrid(
        structure.positions, structure.expanded_radii(args.probe_radius), args.cell_size
    )
    t2 = time.perf_counter()
    lo, hi = structure.bbox()
    fallback = [i for i, e in enumerate(structure.elements) if not has_bondi_radius(str(e))]
    summary = {
        "name": structure.name,
        "source": structure.source,
        "sha256": structure.sha256,
        "n_atoms": structure.n_atoms,
        "n_chains": structure.n_chains,
        "n_residues": structure.n_residues,
        "n_hetero_atoms": int(structure.is_hetero.sum()),
        "elements": sorted({str(e) for e in structure.elements}),
        "fallback_radius_atoms": len(fallback),
        "bbox_min": lo.tolist(),
        "bbox_max": hi.tolist(),
        "backbone_segments": len(structure.backbone),
        "backbone_atoms": int(sum(len(s) for s in structure.backbone)),
        "probe_radius": args.probe_radius,
        "load_seconds": t1 - t0,
        "grid_seconds": t2 - t1,
        "grid": grid.stats().as_dict(),
    }
    if args.json:
        print(json.dumps(summary))
        return 0
    g = summary["grid"]
    print(f"{structure.name}  ({structure.source})")
    print(
        f"  atoms      {structure.n_atoms}  ({summary['n_hetero_atoms']} hetero)  "
        f"elements {', '.join(summary['elements'])}"
    )
    print(
        f"  chains     {structure.n_chains}   residues {structure.n_residues}   "
        f"backbone segments {summary['backbone_segments']}"
    )
    print(f"  bounds     {_fmt(lo)} .. {_fmt(hi)} Å")
    if fallback:
        print(
            f"  radii      {len(fallback)} atom(s) without a Bondi radius use "
            f"{FALLBACK_RADIUS:.2f} Å"
        )
    print(
        f"  grid       cell {g['cell_size']:.2f} Å, {g['dims'][0]}x{g['dims'][1]}x{g['dims'][2]} = "
        f"{g['n_cells']} cells, {g['n_nonempty']} non-empty, max {g['max_per_cell']} / "
        f"mean {g['mean_per_nonempty']:.1f} spheres per non-empty cell, {g['bytes'] / 1024:.1f} KiB"
    )
    print(
        f"  timing     load {summary['load_seconds'] * 1e3:.1f} ms, grid "
        f"{summary['grid_seconds'] * 1e3:.1f} ms"
    )
    return 0


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.1f}" for x in v) + ")"
