"""The haptics benchmark's stability map: the `press` script on crambin at each control
rate x stiffness, per method, and where each injects energy into the arm (unstable) or
lets the hand through the surface (pop-through); its chart and its table."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sasprobe.cli.bench import BenchContext
from sasprobe.protocol.scene import HAPTIC_METHODS as METHODS

RATES_HZ = (100, 250, 500, 1000, 2000, 4000)
STIFFNESS = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0)
QUICK_STIFFNESS = (0.2, 0.5, 1.0, 2.0, 5.0, 12.0)
SMOKE_RATES_HZ, SMOKE_STIFFNESS = (1000,), (0.5, 2.0)
ENERGY_UNSTABLE_MJ = 1.0  # net energy put into the arm over a press-and-release cycle
POP_THROUGH_N = 0.2  # force component along the push: the surface pulls the hand in


def stability_map(ctx: BenchContext) -> dict:
    """Press-and-release on crambin at each control rate x stiffness, per method."""
    from sasprobe.daemon.haptics import HapticSettings
    from sasprobe.daemon.haptics.settings import STIFFNESS_MARGIN, passivity_bound
    from sasprobe.devices.base import PHANTOM_OMNI_LIMITS
    from sasprobe.devices.simulated.arm import ArmModel
    from sasprobe.molecule import load_default

    structure = load_default()
    stiffness, rates = (
        (SMOKE_STIFFNESS, SMOKE_RATES_HZ)
        if ctx.smoke
        else (QUICK_STIFFNESS if ctx.quick else STIFFNESS, RATES_HZ)
    )
    # explore beyond the arm's rated stiffness to show where the frontier lies
    limits = dataclasses.replace(PHANTOM_OMNI_LIMITS, max_stiffness_n_per_mm=max(stiffness))
    cells = []
    for method in METHODS:
        for rate in rates:
            for k in stiffness:
                cells.append(stability_cell(structure, method, rate, k, limits))
    arm = ArmModel()
    damping = HapticSettings().damping_n_s_per_m
    return {
        "structure": structure.name,
        "script": "press",
        "rates_hz": list(rates),
        "stiffness_n_per_mm": list(stiffness),
        "device_max_stiffness_n_per_mm": PHANTOM_OMNI_LIMITS.max_stiffness_n_per_mm,
        "virtual_damping_n_s_per_m": damping,
        "physical_damping_n_s_per_m": arm.arm_damping_n_s_per_m + arm.hand_damping_n_s_per_m,
        # the daemon's default on an arm rated above the bound: half the bound
        "default_stiffness_n_per_mm": {
            str(r): STIFFNESS_MARGIN * passivity_bound(PHANTOM_OMNI_LIMITS, r, damping)
            for r in rates
        },
        "energy_unstable_mj": ENERGY_UNSTABLE_MJ,
        "pop_through_n": POP_THROUGH_N,
        "cells": cells,
    }


def stability_cell(structure, method, rate, stiffness, limits) -> dict:
    from sasprobe.daemon.haptics import HapticEngine, HapticSettings
    from sasprobe.devices.simulated.arm import ArmModel, make_simulated

    # The whole molecule, and a hand without a person's limit: where each method breaks.
    fit = {"cube_half_A": "fit"}
    device = make_simulated(
        "press",
        structure=structure,
        rate_hz=rate,
        limits=limits,
        arm=ArmModel(max_hand_force_n=math.inf),
        **fit,
    )
    engine = HapticEngine(
        structure, limits, HapticSettings(method=method, stiffness_n_per_mm=stiffness, **fit)
    )
    push = np.asarray(device.hand_path.info["push_direction"])
    device.open()
    along = 0.0
    for _ in range(int(round(device.hand_path.duration_s * rate))):
        out = engine.step(device.read())
        device.write_force(out.force_n)
        along = max(along, float(out.force_n @ push))
    return {
        "method": method,
        "rate_hz": rate,
        "stiffness_n_per_mm": stiffness,
        "energy_mj": device.work_mj,
        "max_force_along_push_n": along,
        "unstable": device.work_mj > ENERGY_UNSTABLE_MJ,
        "pop_through": along > POP_THROUGH_N,
    }


def stability_figure(stability):
    from sasprobe.cli.bench.charts import pyplot

    plt = pyplot()
    from matplotlib.colors import ListedColormap

    rates, ks = stability["rates_hz"], stability["stiffness_n_per_mm"]
    fig, axes = plt.subplots(1, 2, figsize=(9.6, 4.0), dpi=110, sharey=True)
    # stable, pop, unstable, both
    cmap = ListedColormap(["#7fc97f", "#fdc086", "#e06666", "#a83232"])
    for ax, method in zip(axes, METHODS):
        grid = np.zeros((len(ks), len(rates)))
        for c in stability["cells"]:
            if c["method"] != method:
                continue
            i, j = ks.index(c["stiffness_n_per_mm"]), rates.index(c["rate_hz"])
            grid[i, j] = (1 if c["pop_through"] else 0) + (2 if c["unstable"] else 0)
            ax.text(j, i, f"{c['energy_mj']:.1f}", ha="center", va="center", fontsize=7)
        ax.imshow(grid, origin="lower", cmap=cmap, vmin=0, vmax=3, aspect="auto")
        ax.set_xticks(range(len(rates)), [str(r) for r in rates])
        ax.set_yticks(range(len(ks)), [f"{k:g}" for k in ks])
        ax.set_xlabel("control rate (Hz)")
        ax.set_title(method)
        # passivity bound K < 2 (b - B) / T (Colgate & Schenkel) and the arm's rated stiffness
        b = stability["physical_damping_n_s_per_m"] - stability["virtual_damping_n_s_per_m"]
        bound = [2 * b * r / 1000.0 for r in rates]  # N/mm
        ax.plot(
            range(len(rates)),
            np.interp(bound, ks, range(len(ks)), left=-0.5, right=len(ks) - 0.5),
            "k--",
            lw=1,
            label="passivity bound 2(b-B)/T",
        )
        default = [stability["default_stiffness_n_per_mm"][str(r)] for r in rates]
        ax.plot(
            range(len(rates)),
            np.interp(default, ks, range(len(ks)), left=-0.5, right=len(ks) - 0.5),
            "b-",
            lw=1,
            label="default stiffness on an arm rated above it: half the bound",
        )
        dev = np.interp(stability["device_max_stiffness_n_per_mm"], ks, range(len(ks)))
        ax.axhline(dev, color="k", lw=1, ls=":", label="Omni rated max")
    axes[0].set_ylabel("stiffness (N/mm)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.suptitle(
        "Press into 1CRN: green stable, orange pop-through, "
        "red energy gain (mJ per cycle in cells)",
        fontsize=9,
    )
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return fig


def stability_markdown(stability) -> str:
    rates = stability["rates_hz"]
    out = [
        f"Stability map: the `press` script on {stability['structure']} (push into the molecule, "
        "hold, release), per control rate and stiffness. Cell: energy put into the arm over the "
        f"cycle (mJ); **U** = unstable (> {stability['energy_unstable_mj']:g} mJ gained), **P** = "
        f"pop-through (force > {stability['pop_through_n']:g} N along the push). Arm damping + "
        f"hand damping {stability['physical_damping_n_s_per_m']:g} N·s/m, virtual damping "
        f"{stability['virtual_damping_n_s_per_m']:g} N·s/m. The passivity bound 2(b − B)/T is "
        + ", ".join(f"{2 * v:.2g}" for v in stability["default_stiffness_n_per_mm"].values())
        + f" N/mm at {', '.join(f'{r} Hz' for r in rates)}; the daemon's default stiffness is "
        "half the smaller of the bound and the arm's rated maximum (docs/haptics.md).",
        "",
    ]
    for method in METHODS:
        out += [
            f"{method}:",
            "",
            "| N/mm | " + " | ".join(f"{r} Hz" for r in rates) + " |",
            "|---:|" + "---:|" * len(rates),
        ]
        for k in stability["stiffness_n_per_mm"]:
            cells = {
                c["rate_hz"]: c
                for c in stability["cells"]
                if c["method"] == method and c["stiffness_n_per_mm"] == k
            }
            text = []
            for r in rates:
                c = cells[r]
                flag = ("U" if c["unstable"] else "") + ("P" if c["pop_through"] else "")
                text.append(f"{c['energy_mj']:.1f} {flag}".strip())
            out.append(f"| {k:g} | " + " | ".join(text) + " |")
        out.append("")
    return "\n".join(out)
