"""`sasprobe bench lighting`: shadows and ambient occlusion, speed against accuracy.

Everything runs on the GL renderer the machine offers (on CI and in this project's
sessions: Mesa llvmpipe, a CPU rasteriser, so absolute times are CPU times; the ratios
are what carries over). The G-buffers are traced through the grid (RaycastGBuffer), so
the lighting passes are timed alone.
"""

from __future__ import annotations

import numpy as np

from sasprobe.cli.bench import BenchContext, BenchResult
from sasprobe.cli.bench import lighting_ao as ao_bench
from sasprobe.cli.bench import lighting_precomputed as precomputed_bench
from sasprobe.cli.bench import lighting_shadows as shadow_bench
from sasprobe.cli.bench.lighting_scene import (
    fitted_scene,
    gl_context,
    gpu_time,
    scene_with_coverage,
)
from sasprobe.cli.bench.machine import gl_renderer
from sasprobe.cli.bench.render_cases import CUBE_TARGET_ATOMS, cube_for
from sasprobe.cli.reference_data import MISSING, reference_structures
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, load_structure
from sasprobe.render.lighting.path_tracer import PathTracer
from sasprobe.render.lighting.settings import DirectionalLight, PathTracing
from sasprobe.render.lighting.uploaded_grid import UploadedGrid

TITLE = "Lighting: shadows and ambient occlusion, speed vs accuracy"


def add_arguments(parser) -> None:
    parser.add_argument(
        "--probe-light-only",
        action="store_true",
        help="only the lights' shadows: grid walk vs their light buffers",
    )


def _plan(ctx: BenchContext, smallest: str) -> dict:
    if ctx.smoke:  # the smallest structure for every part, tiny frames, one repeat
        one = (smallest,)
        return {
            "ao_id": smallest,
            "ao_size": (32, 24),
            "ref_spp": 64,
            "repeats": 1,
            "sweep_size": (32, 24),
            "sweep_ids": one,
            "cells": (3.2,),
            "scaling_ids": one,
            "heights": (1.0,),
            "distant_size": (24, 18),
            "distant_spp": 64,
            "bake_ids": one,
            "cube_id": smallest,
            "patches": (4,),
            "probe_ids": one,
            "probe_size": (32, 24),
        }
    if ctx.quick:
        return {
            "ao_size": (160, 120),
            "ref_spp": 256,
            "repeats": 3,
            "sweep_size": (96, 72),
            "sweep_ids": ("1crn", "3sn6"),
            "cells": (3.2, 12.8),
            "scaling_ids": ("1crn", "3sn6", "1aon"),
            "heights": (1.0, 4.0, 8.0),
            "distant_size": (96, 72),
            "distant_spp": 64,  # keeps --quick < 5 min
            "bake_ids": ("1crn", "1tii"),
            "patches": (4, 8, 16),
            "probe_ids": ("1crn", "3sn6"),
            "probe_size": (160, 120),
        }
    return {
        "ao_size": (320, 240),
        "ref_spp": 1024,
        "repeats": 7,
        "sweep_size": (200, 150),
        "sweep_ids": ("1crn", "1oky", "3sn6"),
        "cells": (2.0, 3.2, 4.8, 9.6, 16.0, 32.0),
        "scaling_ids": None,
        "heights": (0.5, 1.0, 2.0, 4.0, 6.0, 8.0, 12.0),
        "distant_size": (192, 144),
        "distant_spp": 256,
        "bake_ids": None,
        "patches": (4, 6, 8, 12, 16, 24, 32),
        "probe_ids": ("1crn", "1tii", "1aon", "6zu5"),
        "probe_size": (800, 600),
    }


def run(ctx: BenchContext, args=None) -> BenchResult:
    entries = reference_structures()
    if not entries:
        raise UserError(MISSING)
    try:
        gl = gl_context()
    except Exception as exc:
        raise UserError(f"bench lighting needs OpenGL 4.3 through EGL: {exc}") from None
    plan = _plan(ctx, entries[0].id)
    renderer = gl_renderer() or "unknown GL renderer"
    by_id = {e.id: e for e in entries}
    structures = {}

    def structure(sid):
        if sid not in structures:
            structures[sid] = load_structure(by_id[sid].path)
        return structures[sid]

    if getattr(args, "probe_light_only", False):
        ids = [(i, structure(i)) for i in plan["probe_ids"] if i in by_id]
        rows = shadow_bench.probe_light(gl, ids, plan["probe_size"], plan["repeats"])
        suns = shadow_bench.sun_light(gl, ids, plan["probe_size"], plan["repeats"])
        gl.release()
        data = {
            "gl_renderer": renderer,
            "probe_light": rows,
            "sun_light": suns,
            "probe_light_size": list(plan["probe_size"]),
        }
        return BenchResult(
            "lighting",
            data,
            "\n".join(
                [
                    f"GL renderer: **{renderer}**.",
                    "",
                    *shadow_bench.probe_light_markdown(rows, plan["probe_size"]),
                    "",
                    *shadow_bench.sun_light_markdown(suns, plan["probe_size"]),
                ]
            ),
        )
    steps = progress(range(7), desc="bench lighting", total=7)
    # --- AO: every method vs the reference, on a mid-size protein filling the view
    next(steps)
    ao_id = plan.get("ao_id") or ("1oky" if "1oky" in by_id else entries[0].id)
    grid = UploadedGrid.from_structure(gl, structure(ao_id), DEFAULT_PROBE_RADIUS)
    scene = fitted_scene(grid, plan["ao_size"], fill=1.3)
    ao = ao_bench.pareto(gl, scene, plan["ref_spp"], plan["repeats"])
    tracer = PathTracer.for_structure(grid, structure(ao_id))
    sun = DirectionalLight((0.45, 0.8, 0.4), 2.0)

    def path_trace_frame():
        tracer.reset()
        tracer.accumulate(scene.gbuffer, scene.eye, sun, None, PathTracing(bounces=3, spp=1))

    pt_ms = gpu_time(gl, path_trace_frame, plan["repeats"]) * 1e3
    sweep_patches = precomputed_bench.patch_sweep(gl, scene, plan["patches"], plan["repeats"])
    tracer.release()
    scene.release()
    grid.release()
    # --- AO cost against molecule size
    next(steps)
    ids = plan["scaling_ids"] or tuple(e.id for e in entries)
    scaling_scenes = []
    for sid in [i for i in ids if i in by_id]:
        g = UploadedGrid.from_structure(gl, structure(sid), DEFAULT_PROBE_RADIUS)
        scaling_scenes.append(
            (
                sid,
                structure(sid).n_atoms,
                scene_with_coverage(g, plan["ao_size"], shadow_bench.COVERAGE),
            )
        )
    scaling = ao_bench.analytic_scaling(gl, scaling_scenes, plan["repeats"])
    for _, _, s in scaling_scenes:
        s.release()
        s.grid.release()
    # --- SSAO (and others) against distant occluders
    next(steps)
    distant = ao_bench.distant_occluders(
        gl, plan["heights"], plan["distant_size"], plan["distant_spp"]
    )
    # --- shadows: cell-size sweep
    next(steps)
    sweep = []
    for sid in [i for i in plan["sweep_ids"] if i in by_id]:
        sweep += shadow_bench.cell_sweep(
            gl, sid, structure(sid), plan["sweep_size"], plan["cells"], plan["repeats"]
        )
    # --- shadows bounded by the navigation cube
    next(steps)
    cube = shadow_bench.cube_bounded(
        gl,
        [(sid, structure(sid)) for sid in ids if sid in by_id],
        plan["sweep_size"],
        plan["repeats"],
    )
    # --- the probe light: grid walk vs light buffer
    next(steps)
    probe_structures = [(i, structure(i)) for i in plan["probe_ids"] if i in by_id]
    probe = shadow_bench.probe_light(gl, probe_structures, plan["probe_size"], plan["repeats"])
    suns = shadow_bench.sun_light(gl, probe_structures, plan["probe_size"], plan["repeats"])
    # --- precomputed occlusion: bake time against molecule size
    next(steps)
    bake_ids = [i for i in (plan["bake_ids"] or tuple(e.id for e in entries)) if i in by_id]
    largest = plan.get("cube_id") or max(by_id, key=lambda k: by_id[k].atoms)  # baked for its cube
    bake_structures = [(sid, structure(sid)) for sid in dict.fromkeys([*bake_ids, largest])]
    bakes = precomputed_bench.bake_scaling(
        gl, bake_structures, lambda s: cube_for(s, CUBE_TARGET_ATOMS)
    )
    if plan["bake_ids"] is not None:  # quick: the largest only for its cube
        bakes = [r for r in bakes if r["cube"] or r["structure"] in plan["bake_ids"]]
    gl.release()

    charts = []
    if ctx.out_dir is not None:
        charts = [
            ao_bench.pareto_chart(ao["rows"], ctx.chart_path("lighting_ao_pareto.png"), renderer),
            ao_bench.comparison_figure(
                ao["images"], ao["mask"], ctx.chart_path("lighting_ao_comparison.png")
            ),
            ao_bench.k_chart(ao["analytic_k"], ctx.chart_path("lighting_ao_neighbours.png")),
            ao_bench.noise_chart(
                ao["noise"], ao["images"], ao["mask"], ctx.chart_path("lighting_ao_noise.png")
            ),
            ao_bench.scaling_chart(scaling, ctx.chart_path("lighting_ao_scaling.png")),
            ao_bench.distant_chart(distant, ctx.chart_path("lighting_ao_distant.png")),
            shadow_bench.sweep_chart(sweep, ctx.chart_path("lighting_shadow_cells.png")),
            shadow_bench.cube_chart(cube, ctx.chart_path("lighting_shadow_cube.png")),
            precomputed_bench.scaling_chart(bakes, ctx.chart_path("lighting_precomputed_bake.png")),
            precomputed_bench.patch_chart(
                sweep_patches, ctx.chart_path("lighting_precomputed_patch.png")
            ),
        ]
    data = {
        "gl_renderer": renderer,
        "ao_structure": ao_id,
        "ao_size": list(plan["ao_size"]),
        "reference_spp": plan["ref_spp"],
        "ao": ao["rows"],
        "analytic_k": ao["analytic_k"],
        "noise": ao["noise"],
        "path_trace_1spp_3_bounces_ms": pt_ms,
        "ao_scaling": scaling,
        "distant_occluders": distant,
        "shadow_cells": sweep,
        "shadow_size": list(plan["sweep_size"]),
        "cube_shadows": cube,
        "probe_light": probe,
        "sun_light": suns,
        "probe_light_size": list(plan["probe_size"]),
        "precomputed_bake": bakes,
        "precomputed_patches": sweep_patches,
        **_checks(scaling, sweep, cube),
    }
    return BenchResult("lighting", data, _markdown(data, plan), charts)


def _checks(scaling, sweep, cube) -> dict:
    """The targets, as measured ratios."""
    analytic = np.array([r["analytic_ms"] for r in scaling])
    per_structure = {}
    for r in sweep:
        s = per_structure.setdefault(r["structure"], {"atoms": r["atoms"]})
        if r["default"]:
            s["default_hard_ms"], s["soft_over_hard"] = r["hard_ms"], r["soft_ms"] / r["hard_ms"]
        if r["brute_force"]:
            s["brute_hard_ms"] = r["hard_ms"]
    for s in per_structure.values():
        s["grid_speedup"] = s["brute_hard_ms"] / s["default_hard_ms"]
    cube_ms = np.array([r["cube_hard_ms"] for r in cube])
    return {
        "analytic_spread": float(analytic.max() / analytic.min()),
        "analytic_max_deviation_from_smallest": float(np.max(np.abs(analytic / analytic[0] - 1.0))),
        "shadow_grid": per_structure,
        "cube_spread": float(cube_ms.max() / cube_ms.min()),
        "cube_max_deviation_from_smallest": float(np.max(np.abs(cube_ms / cube_ms[0] - 1.0))),
    }


def _markdown(d: dict, plan: dict) -> str:
    w, h = d["ao_size"]
    lines = [
        f"GL renderer: **{d['gl_renderer']}** (no GPU: a CPU rasteriser; absolute times are CPU "
        "times, "
        "ratios are what carries over). Medians; every ratio comes from the same run.",
        "",
        f"### Ambient occlusion ({d['ao_structure']}, {w}×{h}, error against ray-traced AO "
        "converged at "
        f"{d['reference_spp']} spp, 8 Å rays; molecule pixels)",
        "",
        "| method | ms / frame | RMSE | max error | bias |",
        "|---|---:|---:|---:|---:|",
    ]
    for r in d["ao"]:
        bake = f" (bake {r['bake_s']:.2f} s once)" if r.get("bake_s") is not None else ""
        lines.append(
            f"| {r['method']}{bake} | {r['ms']:.1f} | {r['rmse']:.4f} | {r['max_error']:.3f} | "
            f"{r['bias']:+.4f} |"
        )
    lines += [
        f"| path tracing, 1 spp, 3 bounces (for scale) | {d['path_trace_1spp_3_bounces_ms']:.1f} | "
        "| | |",
        "",
        "Analytic AO against K (too few neighbours): "
        + ", ".join(f"K={r['k']}: RMSE {r['rmse']:.3f}" for r in d["analytic_k"]),
        "",
        "Ray-traced AO noise before/after the bilateral blur: "
        + ", ".join(
            f"{r['spp']} spp {r['raw']['rmse']:.3f} → {r['blurred']['rmse']:.3f}"
            for r in d["noise"]
        ),
        "",
        "### AO cost against molecule size (equal screen coverage: about half the pixels show "
        "atoms)",
        "",
        "| structure | atoms | coverage | analytic K=16 (ms) | analytic K=32 (ms) | SSAO (ms) | RT "
        "1 spp (ms) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in d["ao_scaling"]:
        lines.append(
            f"| {r['structure']} | {r['atoms']} | {r['coverage']:.2f} | {r['analytic_ms']:.2f} | "
            f"{r['analytic32_ms']:.2f} | {r['ssao_ms']:.2f} | {r['rt1_ms']:.2f} |"
        )
    lines += [
        "",
        f"Analytic AO: largest / smallest time {d['analytic_spread']:.2f}; largest deviation from "
        f"{d['ao_scaling'][0]['structure']} {100 * d['analytic_max_deviation_from_smallest']:.0f} "
        "% (target ±20 %).",
        "",
        "### Occluders beyond the sampling radius (AO drop a 5 Å ball casts on a sheet under it)",
        "",
        "| gap (Å) | " + " | ".join(k for k in d["distant_occluders"][0] if k != "height") + " |",
        "|---:|" + "---:|" * (len(d["distant_occluders"][0]) - 1),
    ]
    for r in d["distant_occluders"]:
        lines.append(
            f"| {r['height']:g} | "
            + " | ".join(f"{v:.3f}" for k, v in r.items() if k != "height")
            + " |"
        )
    sw, sh = d["shadow_size"]
    lines += [
        "",
        f"### Shadows against cell count ({sw}×{sh}, directional light; last row per structure: "
        "one cell = brute force)",
        "",
        "| structure | atoms | cell (Å) | cells | grid MiB | hard (ms) | soft (ms) | soft / hard |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in d["shadow_cells"]:
        mark = " (default)" if r["default"] else (" (brute force)" if r["brute_force"] else "")
        lines.append(
            f"| {r['structure']} | {r['atoms']} | {r['cell_size']:.1f}{mark} | {r['cells']} | "
            f"{r['grid_bytes'] / 2**20:.2f} | {r['hard_ms']:.1f} | {r['soft_ms']:.1f} | "
            f"{r['soft_ms'] / r['hard_ms']:.2f} |"
        )
    lines.append("")
    for name, s in d["shadow_grid"].items():
        lines.append(
            f"- {name} ({s['atoms']} atoms): grid {s['grid_speedup']:.1f}× faster than brute force "
            f"(target ≥ 20× at ~10k atoms); soft / hard {s['soft_over_hard']:.2f} (target ≤ 1.30)"
        )
    lines += [
        "",
        f"### Shadows bounded by a {2 * shadow_bench.CUBE_HALF:g} Å navigation cube ({sw}×{sh}, "
        "camera framing "
        "the cube; whole molecule for contrast; equal screen coverage)",
        "",
        "| structure | atoms | atoms in cube | coverage | hard (ms) | soft (ms) | whole molecule "
        "hard (ms) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in d["cube_shadows"]:
        lines.append(
            f"| {r['structure']} | {r['atoms']} | {r['cube_atoms']} | {r['cube_coverage']:.2f} | "
            f"{r['cube_hard_ms']:.2f} | "
            f"{r['cube_soft_ms']:.2f} | {r['whole_hard_ms']:.2f} |"
        )
    lines += [
        "",
        f"Cube-bounded hard shadows: largest / smallest time {d['cube_spread']:.2f}; largest "
        "deviation "
        f"from {d['cube_shadows'][0]['structure']} "
        f"{100 * d['cube_max_deviation_from_smallest']:.0f} %.",
    ]
    lines += [
        "",
        *shadow_bench.probe_light_markdown(d["probe_light"], d["probe_light_size"]),
        "",
        *shadow_bench.sun_light_markdown(d["sun_light"], d["probe_light_size"]),
    ]
    lines += [
        "",
        precomputed_bench.markdown(
            d["precomputed_bake"], d["precomputed_patches"], d["ao_structure"], d["ao_size"]
        ),
    ]
    return "\n".join(lines)
