"""`sasprobe bench haptics`: the proxy against the penalty baseline on the simulated arm.

Per reference structure and method: per-tick force-computation time (p50/p99/max µs), the
deepest the rendered contact point gets into the SAS, force continuity (largest force
change between consecutive ticks), and the energy the rendering put into the arm
(sum of F . dx over each held period). Then the stability map over control rate x
stiffness (haptics_stability.py): where each method injects energy or pops through.

Timing: sessions run closed-loop (sim arm <-> engine); the recorded device states
are then replayed through fresh engines `repeats` times and each tick's time is the
minimum over the replays. `step` is deterministic, so every replay does the same work
and the minimum removes time stolen by other processes on a shared machine; the
single-run p99 is reported beside it.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sasprobe.cli.argtypes import positive_float, positive_int
from sasprobe.cli.bench import BenchContext, BenchResult
from sasprobe.cli.bench.haptics_stability import stability_figure, stability_map, stability_markdown
from sasprobe.cli.reference_data import MISSING, reference_structures
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress
from sasprobe.molecule import load_structure
from sasprobe.protocol.scene import HAPTIC_METHODS as METHODS

TITLE = "Haptic rendering: per-tick cost, penetration, continuity, passivity, stability"

SCRIPTS = ("scan", "random")  # timing and accuracy sessions
CUBE_HALF_A = 20.0  # the same zoom (Å per mm) for every structure, so sizes compare fairly
QUICK_IDS = ("1crn", "1tii", "1aon", "6zu5")


def _cube_half(text: str) -> float:
    return 0.0 if text.strip() == "0" else positive_float(text)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--structures", help="comma-separated reference structure ids (default: all; --quick: 4)"
    )
    parser.add_argument(
        "--ticks",
        type=positive_int,
        help="control ticks per timing session (default 10000, --quick 3000)",
    )
    parser.add_argument(
        "--repeats", type=positive_int, help="timing replays per session (default 5, --quick 3)"
    )
    parser.add_argument("--no-map", action="store_true", help="skip the stability map")
    parser.add_argument(
        "--cube-half",
        type=_cube_half,
        default=CUBE_HALF_A,
        help=f"navigation cube half edge in Å on the top surface (default {CUBE_HALF_A:g}; 0 = "
        "fit the molecule)",
    )


def run(ctx: BenchContext, args: argparse.Namespace | None = None) -> BenchResult:
    ticks = getattr(args, "ticks", None) or (300 if ctx.smoke else 3000 if ctx.quick else 10000)
    repeats = getattr(args, "repeats", None) or (1 if ctx.smoke else 3 if ctx.quick else 5)
    entries = _entries(getattr(args, "structures", None), ctx)
    cube_half = getattr(args, "cube_half", CUBE_HALF_A)
    rows = []
    for entry in progress(entries, desc="bench haptics", total=len(entries)):
        structure = load_structure(entry.path)
        for method in METHODS:
            rows.append(_structure_row(entry.id, structure, method, ticks, repeats, cube_half))
    stability = None if getattr(args, "no_map", False) else stability_map(ctx)
    trace = _force_trace(1000 if ctx.smoke else 4000)
    charts = _charts(ctx, rows, stability, trace, cube_half)
    data = {
        "ticks_per_session": ticks,
        "repeats": repeats,
        "cube_half_A": cube_half or None,
        "rows": rows,
    }
    if stability is not None:
        data["stability"] = stability
    return BenchResult(
        "haptics", data, _markdown(rows, stability, ticks, repeats, cube_half), charts
    )


def _entries(ids: str | None, ctx: BenchContext):
    entries = reference_structures()
    if not entries:
        raise UserError(MISSING)
    if ctx.smoke and not ids:
        return entries[:1]
    wanted = (
        [i.strip() for i in ids.split(",")] if ids else (list(QUICK_IDS) if ctx.quick else None)
    )
    if wanted is None:
        return entries
    by_id = {e.id: e for e in entries}
    unknown = [i for i in wanted if i not in by_id]
    if unknown:
        raise UserError(
            f"unknown reference structure(s): {', '.join(unknown)} (known: {', '.join(by_id)})"
        )
    return [by_id[i] for i in wanted]


# ------------------------------------------------------------------ sessions
def closed_loop_session(
    structure, script, method, settings_kw, limits, ticks, rate_hz=1000, seed=1
):
    """Closed loop sim arm <-> engine; returns the states, outputs and the arm."""
    from sasprobe.daemon.haptics import HapticEngine, HapticSettings
    from sasprobe.devices.simulated.arm import make_simulated

    device = make_simulated(
        script, structure=structure, rate_hz=rate_hz, seed=seed, limits=limits, **settings_kw
    )
    engine = HapticEngine(structure, limits, HapticSettings(method=method, **settings_kw))
    device.open()
    states, outputs = [], []
    for _ in range(ticks):
        state = device.read()
        out = engine.step(state)
        device.write_force(out.force_n)
        states.append(state)
        outputs.append(out)
    device.close()
    return states, outputs, device


def _replay_times(
    structure, method, settings_kw, limits, states, repeats
) -> tuple[np.ndarray, np.ndarray]:
    """(per-tick minimum over replays, first replay) in µs."""
    from sasprobe.daemon.haptics import HapticEngine, HapticSettings

    runs = []
    for _ in range(repeats):
        engine = HapticEngine(structure, limits, HapticSettings(method=method, **settings_kw))
        step = engine.step
        clock = time.perf_counter_ns
        times = np.empty(len(states))
        for k, state in enumerate(states):
            t0 = clock()
            step(state)
            times[k] = clock() - t0
        runs.append(times / 1e3)
    return np.min(runs, axis=0), runs[0]


def _penetration(grid, points: np.ndarray) -> float:
    """Deepest any point is inside an expanded sphere (Å, 0 when none is)."""
    worst = 0.0
    for p in points:
        idx = grid.spheres_within(p, 0.0)
        if idx.size:
            depth = grid.radii[idx] - np.linalg.norm(grid.centers[idx] - p, axis=1)
            worst = max(worst, float(depth.max()))
    return worst


def _structure_row(entry_id, structure, method, ticks, repeats, cube_half) -> dict:
    from sasprobe.daemon.haptics import HapticEngine, HapticSettings
    from sasprobe.devices.base import PHANTOM_OMNI_LIMITS
    from sasprobe.molecule.surface import surface_site

    limits = PHANTOM_OMNI_LIMITS
    settings_kw = (
        {"cube_half_A": cube_half, "cube_center_A": surface_site(structure, cube_half)}
        if cube_half
        else {"cube_half_A": "fit"}
    )
    t0 = time.perf_counter()
    engine = HapticEngine(structure, limits, HapticSettings(method=method, **settings_kw))
    setup_s = time.perf_counter() - t0
    best, single = [], []
    penetration = jump_max = 0.0
    jumps = []
    energy = contact = clamped = 0.0
    for script in SCRIPTS:
        states, outputs, device = closed_loop_session(
            structure, script, method, settings_kw, limits, ticks
        )
        b, s = _replay_times(structure, method, settings_kw, limits, states, repeats)
        best.append(b)
        single.append(s)
        forces = np.array([o.force_n for o in outputs])
        contacts = [o.proxy_A for o in outputs if o.contact]
        penetration = max(penetration, _penetration(engine.grid, contacts))
        d = np.linalg.norm(np.diff(forces, axis=0), axis=1)
        jumps.append(d)
        jump_max = max(jump_max, float(d.max()))
        energy += device.work_mj
        contact += sum(o.contact for o in outputs)
        clamped += sum(o.clamped for o in outputs)
    best_all, single_all, jumps_all = (
        np.concatenate(best),
        np.concatenate(single),
        np.concatenate(jumps),
    )
    n = len(best_all)
    return {
        "id": entry_id,
        "n_atoms": structure.n_atoms,
        "method": method,
        "scale_A_per_mm": engine.mapping.scale_A_per_mm,
        "setup_s": setup_s,
        "ticks": n,
        "p50_us": float(np.percentile(best_all, 50)),
        "p99_us": float(np.percentile(best_all, 99)),
        "max_us": float(best_all.max()),
        "single_run_p99_us": float(np.percentile(single_all, 99)),
        "max_penetration_A": penetration,
        "max_force_step_n": jump_max,
        "p99_force_step_n": float(np.percentile(jumps_all, 99)),
        "energy_mj": energy,
        "contact_fraction": contact / n,
        "clamped_fraction": clamped / n,
    }


def _force_trace(ticks: int) -> dict:
    """Force magnitude through a dive into a groove on crambin, both methods (for a chart)."""
    from sasprobe.devices.base import PHANTOM_OMNI_LIMITS
    from sasprobe.molecule import load_default

    structure = load_default()
    trace = {}
    for method in METHODS:
        _, outputs, device = closed_loop_session(
            structure, "dive", method, {"cube_half_A": "fit"}, PHANTOM_OMNI_LIMITS, ticks=ticks
        )
        trace[method] = [float(np.linalg.norm(o.force_n)) for o in outputs]
    return trace


# -------------------------------------------------------------- charts, text
def _charts(ctx: BenchContext, rows, stability, trace, cube_half) -> list:
    from sasprobe.cli.bench.charts import figure, save

    charts = []
    path = ctx.chart_path("haptics_tick_time.png")
    if path is not None:
        fig, ax = figure()
        for method, marker, color in zip(METHODS, "os", ("tab:blue", "tab:orange")):
            sel = [r for r in rows if r["method"] == method]
            atoms = [r["n_atoms"] for r in sel]
            ax.semilogx(
                atoms, [r["p50_us"] for r in sel], marker + "-", color=color, label=f"{method} p50"
            )
            ax.semilogx(
                atoms,
                [r["p99_us"] for r in sel],
                marker + "--",
                color=color,
                mfc="none",
                label=f"{method} p99",
            )
        ax.axhline(100, color="red", lw=1, ls=":", label="target p99 100 µs")
        ax.set_xlabel("atoms")
        ax.set_ylabel("force computation per tick (µs)")
        ax.set_title(
            "Per-tick cost vs molecule size "
            f"({f'same {cube_half:g} Å cube' if cube_half else 'fitted cube'})"
        )
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=8)
        charts.append(save(fig, path))
    path = ctx.chart_path("haptics_stability.png")
    if path is not None and stability is not None:
        charts.append(save(stability_figure(stability), path))
    path = ctx.chart_path("haptics_dive_force.png")
    if path is not None:
        fig, ax = figure(6.4, 3.2)
        for method in METHODS:
            t = np.arange(len(trace[method])) / 1000.0
            ax.plot(t, trace[method], lw=0.9, label=method)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("|force| (N)")
        ax.set_title("Dive into a groove on 1CRN and rock across it (1 kHz)")
        ax.legend()
        charts.append(save(fig, path))
    return charts


def _markdown(rows, stability, ticks, repeats, cube_half) -> str:
    cube = (
        f"navigation cube half edge {cube_half:g} Å on "
        "the top surface of every structure (same Å/mm)"
        if cube_half
        else "navigation cube fitted to each molecule (Å/mm grows with size)"
    )
    lines = [
        f"Simulated arm, 1 kHz, scripts {' + '.join(SCRIPTS)} ({ticks} ticks each), {cube}. "
        f"Per-tick time: minimum over {repeats} replays of the recorded states (single-run p99 "
        "beside it). Penetration: deepest the rendered contact point gets inside any expanded "
        "sphere. Force step: largest change between consecutive ticks. Energy: sum of F·dx the "
        "rendering put into the arm (negative = it absorbed energy).",
        "",
        "| structure | atoms | Å/mm | method | p50 (µs) | p99 (µs) | max (µs) | single-run p99 "
        "(µs) | setup (s) | max penetration (Å) | max force step (N) | p99 force step (N) | "
        "energy (mJ) | contact |",
        "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['id']} | {r['n_atoms']} | {r['scale_A_per_mm']:.2f} | {r['method']} | "
            f"{r['p50_us']:.1f} | {r['p99_us']:.1f} | {r['max_us']:.0f} | "
            f"{r['single_run_p99_us']:.1f} | {r['setup_s']:.2f} | {r['max_penetration_A']:.2g} | "
            f"{r['max_force_step_n']:.3f} | {r['p99_force_step_n']:.3f} | {r['energy_mj']:.1f} | "
            f"{r['contact_fraction']:.0%} |"
        )
    if stability is not None:
        lines += ["", stability_markdown(stability)]
    return "\n".join(lines)
