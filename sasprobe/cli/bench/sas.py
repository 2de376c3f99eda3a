"""`sasprobe bench sas`: Shrake-Rupley SAS time and accuracy against FreeSASA, same run."""

from __future__ import annotations

import numpy as np

from sasprobe.cli.bench import BenchContext, BenchResult, median_time
from sasprobe.cli.bench.charts import annotate_apart, figure, save
from sasprobe.cli.reference_data import MISSING, reference_structures
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress
from sasprobe.molecule import UniformGrid, load_structure
from sasprobe.molecule.sas import ACCESSIBLE_MIN_AREA, shrake_rupley

TITLE = "Solvent accessible surface area (Shrake-Rupley vs FreeSASA)"
MAX_ATOMS = 70_000  # FreeSASA's Python wrapper takes minutes beyond this
QUICK_MAX_ATOMS = 25_000  # --quick: the ~60k-atom entry alone takes half the run


def run(ctx: BenchContext) -> BenchResult:
    try:
        import freesasa
    except ImportError:
        raise UserError("bench sas needs FreeSASA as the reference: pip install freesasa") from None
    max_atoms = QUICK_MAX_ATOMS if ctx.quick else MAX_ATOMS
    entries = [e for e in reference_structures() if e.atoms <= max_atoms]
    if not entries:
        raise UserError(MISSING)
    if ctx.smoke:
        entries = entries[:1]
    repeats = 1 if ctx.quick else 3
    rows = []
    for entry in progress(entries, desc="bench sas", total=len(entries)):
        s = load_structure(entry.path)
        result = {}

        # bound to this entry (B023): median_time calls them before the next one
        def ours(s=s, result=result):
            result["sr"] = shrake_rupley(UniformGrid(s.positions, s.expanded_radii(1.4)))

        def reference(s=s, result=result):
            params = freesasa.Parameters(
                {"algorithm": freesasa.LeeRichards, "probe-radius": 1.4, "n-slices": 100}
            )
            r = freesasa.calcCoord(s.positions.ravel(), s.vdw_radii, params)
            result["ref"] = np.array([r.atomArea(i) for i in range(s.n_atoms)])

        ours_s = median_time(ours, repeats)
        ref_s = median_time(reference, repeats)
        sr, ref = result["sr"], result["ref"]
        rows.append(
            {
                "id": entry.id,
                "n_atoms": s.n_atoms,
                "ours_s": ours_s,
                "freesasa_s": ref_s,
                "total_rel_error": sr.total / ref.sum() - 1.0,
                "flags_agree": float(np.mean(sr.accessible == (ref >= ACCESSIBLE_MIN_AREA))),
                "flags_agree_area_gt_0": float(np.mean((sr.areas > 0) == (ref > 0))),
                "max_atom_error_A2": float(np.abs(sr.areas - ref).max()),
            }
        )
    charts = []
    path = ctx.chart_path("sas_speed_accuracy.png")
    if path is not None:
        fig, ax = figure()
        atoms = [r["n_atoms"] for r in rows]
        ax.loglog(
            atoms,
            [r["ours_s"] for r in rows],
            "o-",
            label="sasprobe Shrake-Rupley (512 pts + refine)",
        )
        ax.loglog(
            atoms, [r["freesasa_s"] for r in rows], "s-", label="FreeSASA Lee-Richards (100 slices)"
        )
        ax.set_xlabel("atoms")
        ax.set_ylabel("median time (s)")
        ax.set_title("SAS time (labels: |total area difference|)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        annotate_apart(
            ax,
            [(r["n_atoms"], r["ours_s"], f"{abs(r['total_rel_error']) * 100:.2f}%") for r in rows],
            fontsize=7,
        )
        charts.append(save(fig, path))
    lines = [
        "| structure | atoms | sasprobe (s) | FreeSASA LR (s) | ratio | total area diff | flags "
        "agree (≥ 0.5 Å²) | flags agree (> 0) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['id']} | {r['n_atoms']} | {r['ours_s']:.2f} | {r['freesasa_s']:.2f} | "
            f"{r['ours_s'] / r['freesasa_s']:.2f} | {r['total_rel_error'] * 100:+.3f} % | "
            f"{r['flags_agree'] * 100:.2f} % | {r['flags_agree_area_gt_0'] * 100:.2f} % |"
        )
    markdown = (
        "Same spheres (Bondi radii + 1.4 Å probe) in both; medians of "
        f"{repeats} run(s); FreeSASA's time includes its Python per-atom readout.\n\n"
        + "\n".join(lines)
    )
    return BenchResult("sas", {"structures": rows}, markdown, charts)
