"""Ambient-occlusion part of `sasprobe bench lighting`: every method and setting timed per
frame and compared with the converged ray-traced reference (Pareto chart; precomputed
occlusion by its per-frame lookup, its one-off bake reported beside), analytic AO against
molecule size, and where methods fail (SSAO and distant occluders, analytic AO with few
neighbours, 1-spp noise before and after the blur)."""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import numpy as np

from sasprobe.cli.bench.charts import annotate_apart, figure, pyplot, save
from sasprobe.cli.bench.lighting_scene import (
    Scene,
    cost_vs_size_chart,
    interleaved_times,
    oblique_camera,
    spheres_grid,
    trace_scene,
)
from sasprobe.render.gl.textures import read_texture
from sasprobe.render.lighting.ao import AmbientOcclusion
from sasprobe.render.lighting.settings import AOSettings

BASE = AOSettings()
# (patch side, directions); QuteMol: 128 directions
PRECOMPUTED = (
    (6, 64),
    (8, 32),
    (8, 64),
    (12, 64),
    (16, 64),
    (16, 128),
)
PRECOMPUTED_SHOWN = f"precomputed {BASE.patch}x{BASE.patch}, {BASE.directions} dirs"


SCALING_SERIES = [  # (row key, label, line style) of scaling_chart
    ("analytic_ms", "analytic K=16", "o-"),
    ("analytic32_ms", "analytic K=32", "o:"),
    ("ssao_ms", "SSAO point, 16 samples", "s-"),
    ("rt1_ms", "RT 1 spp (8 Å rays)", "^-"),
]


def methods() -> list[tuple[str, str, AOSettings]]:
    """(label, family, settings) of every AO variant measured."""
    out = [
        (f"analytic K={k}", "analytic", replace(BASE, mode="analytic", k=k)) for k in (8, 16, 32)
    ]
    for sampling in ("point", "line"):
        for half in (False, True):
            out.append(
                (
                    f"SSAO {sampling} 4 Å {'half' if half else 'full'}",
                    "ssao",
                    replace(BASE, mode="ssao", ssao_sampling=sampling, ssao_half_resolution=half),
                )
            )
    out += [
        (f"SSAO point {r:g} Å full", "ssao", replace(BASE, mode="ssao", ssao_radius=r))
        for r in (2.0, 8.0)
    ]
    out.append(("RT 1 spp raw", "rt", replace(BASE, mode="rt", rt_spp=1, blur=False)))
    out += [
        (f"RT {n} spp{' + blur' if n < 16 else ''}", "rt", replace(BASE, mode="rt", rt_spp=n))
        for n in (1, 4, 16, 64)
    ]
    out.append(("hybrid K=32 × RT 1 spp", "hybrid", replace(BASE, mode="hybrid", rt_spp=1)))
    out += [
        (
            f"precomputed {p}x{p}, {d} dirs",
            "precomputed",
            replace(BASE, mode="precomputed", patch=p, directions=d),
        )
        for p, d in PRECOMPUTED
    ]
    return out


def one_frame(ao: AmbientOcclusion, scene: Scene, settings: AOSettings):
    """The accessibility of one frame from scratch (accumulation restarted)."""
    ao.configure(settings)
    ao.view_changed()
    return ao.compute(scene.gbuffer, scene.view, scene.proj)


def reference(
    ao: AmbientOcclusion, scene: Scene, total: int, distance: float = BASE.distance
) -> np.ndarray:
    ao.configure(
        replace(BASE, mode="reference", distance=distance, reference_spp=64, reference_total=total)
    )
    ao.view_changed()
    while not ao.converged:
        texture = ao.compute(scene.gbuffer, scene.view, scene.proj)
    return read_texture(texture).copy()


def errors(image: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> dict:
    diff = image[mask] - ref[mask]
    return {
        "rmse": float(np.sqrt(np.mean(diff**2))),
        "max_error": float(np.max(np.abs(diff))),
        "bias": float(diff.mean()),
    }


def pareto(gl, scene: Scene, ref_spp: int, repeats: int) -> dict:
    """Every method's frame time and error; the K sweep; the noise sweep; the images."""
    ao = AmbientOcclusion(scene.grid)
    mask = scene.atom != -1
    ref = reference(ao, scene, ref_spp)
    rows, images = [], {"reference": ref}
    listed = methods()
    # each precomputed variant keeps its own atlas: the interleaved frames then time its lookup,
    # the warm-up frame its bake
    own = {
        label: AmbientOcclusion(scene.grid)
        for label, family, _ in listed
        if family == "precomputed"
    }
    seconds = interleaved_times(
        gl,
        {
            label: partial(one_frame, own.get(label, ao), scene, settings)
            for label, _, settings in listed
        },
        repeats,
    )
    for label, family, settings in listed:
        image = read_texture(one_frame(own.get(label, ao), scene, settings)).copy()
        images[label] = image
        bake = own[label].program("atlas").bake_seconds if label in own else None
        rows.append(
            {
                "method": label,
                "family": family,
                "ms": seconds[label] * 1e3,
                "bake_s": bake,
                **errors(image, ref, mask),
            }
        )
    for extra in own.values():
        extra.release()
    # failure mode: analytic AO with too few neighbours
    k_rows = []
    for k in (1, 2, 4, 8, 16, 32):
        image = read_texture(one_frame(ao, scene, replace(BASE, mode="analytic", k=k)))
        k_rows.append({"k": k, **errors(image, ref, mask)})
    # failure mode: noise at low sample counts, before and after the bilateral blur
    noise_rows = []
    for spp in (1, 2, 4, 8):
        raw = read_texture(
            one_frame(ao, scene, replace(BASE, mode="rt", rt_spp=spp, blur=False))
        ).copy()
        blurred = read_texture(
            one_frame(ao, scene, replace(BASE, mode="rt", rt_spp=spp, blur=True))
        ).copy()
        images[f"RT {spp} spp raw"] = raw
        images[f"RT {spp} spp + blur"] = blurred
        noise_rows.append(
            {"spp": spp, "raw": errors(raw, ref, mask), "blurred": errors(blurred, ref, mask)}
        )
    ao.release()
    return {"rows": rows, "analytic_k": k_rows, "noise": noise_rows, "images": images, "mask": mask}


# ------------------------------------------------------------------ charts
FAMILY_STYLE = {
    "analytic": ("tab:blue", "o"),
    "ssao": ("tab:orange", "s"),
    "rt": ("tab:green", "^"),
    "hybrid": ("tab:purple", "D"),
    "precomputed": ("tab:red", "P"),
}


def pareto_chart(rows: list[dict], path, renderer: str):
    fig, ax = figure(7.5, 5.0)
    for family, (color, marker) in FAMILY_STYLE.items():
        pts = [r for r in rows if r["family"] == family]
        ax.scatter(
            [r["ms"] for r in pts],
            [r["rmse"] for r in pts],
            c=color,
            marker=marker,
            label=family,
            zorder=3,
        )
    front, best = [], np.inf
    for r in sorted(rows, key=lambda r: r["ms"]):
        if r["rmse"] < best:
            best = r["rmse"]
            front.append(r)
    front_ms, front_rmse = [r["ms"] for r in front], [r["rmse"] for r in front]
    ax.step(front_ms, front_rmse, where="post", color="0.4", lw=1, ls="--", label="Pareto front")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(
        "time per frame (ms, median; precomputed: the lookup, its bake once per structure and "
        "culling)"
    )
    ax.set_ylabel("RMSE vs converged ray-traced AO")
    ax.set_title(f"Ambient occlusion: speed vs accuracy\n({renderer})", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    annotate_apart(
        ax,
        [
            (
                r["ms"],
                r["rmse"],
                r["method"]
                + (f" (bake {r['bake_s']:.2f} s)" if r.get("bake_s") is not None else ""),
            )
            for r in sorted(rows, key=lambda r: r["ms"])
        ],
    )
    return save(fig, path)


def comparison_figure(images: dict, mask: np.ndarray, path):
    plt = pyplot()

    shown = [
        "analytic K=32",
        "SSAO point 4 Å full",
        "SSAO line 4 Å full",
        "RT 1 spp + blur",
        "hybrid K=32 × RT 1 spp",
        PRECOMPUTED_SHOWN,
        "reference",
    ]
    fig, axes = plt.subplots(2, len(shown), figsize=(2.3 * len(shown), 4.2), dpi=110)
    ref = images["reference"]
    for col, name in enumerate(shown):
        img = np.where(mask, images[name], 1.0)[::-1]
        axes[0, col].imshow(img, cmap="gray", vmin=0, vmax=1)
        axes[0, col].set_title(name, fontsize=7)
        err = np.where(mask, images[name] - ref, 0.0)[::-1]
        im = axes[1, col].imshow(err, cmap="RdBu_r", vmin=-0.5, vmax=0.5)
        axes[1, col].set_title("error" if name != "reference" else "(reference)", fontsize=7)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes[1, :].tolist(), shrink=0.8, label="method − reference")
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path


def k_chart(k_rows: list[dict], path):
    fig, ax = figure()
    ax.plot([r["k"] for r in k_rows], [r["rmse"] for r in k_rows], "o-", label="RMSE")
    ax.plot([r["k"] for r in k_rows], [r["max_error"] for r in k_rows], "s--", label="max |error|")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("neighbours per atom (K)")
    ax.set_ylabel("error vs reference")
    ax.set_title("Analytic AO with too few neighbours")
    ax.legend()
    return save(fig, path)


def noise_chart(noise_rows: list[dict], images: dict, mask: np.ndarray, path):
    plt = pyplot()

    fig, axes = plt.subplots(
        1, 4, figsize=(11, 2.8), dpi=110, gridspec_kw={"width_ratios": [1.6, 1, 1, 1]}
    )
    spp = [r["spp"] for r in noise_rows]
    axes[0].plot(spp, [r["raw"]["rmse"] for r in noise_rows], "o-", label="raw")
    axes[0].plot(spp, [r["blurred"]["rmse"] for r in noise_rows], "s-", label="bilateral blur")
    axes[0].set_xscale("log", base=2)
    axes[0].set_xlabel("samples per pixel")
    axes[0].set_ylabel("RMSE vs reference")
    axes[0].grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    h, w = mask.shape
    crop = (slice(h // 4, 3 * h // 4), slice(w // 4, 3 * w // 4))
    for ax, name in zip(axes[1:], ("RT 1 spp raw", "RT 1 spp + blur", "reference")):
        ax.imshow(np.where(mask, images[name], 1.0)[crop][::-1], cmap="gray", vmin=0, vmax=1)
        ax.set_title(name, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle("1-spp ray-traced AO: noise before and after the bilateral blur", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


# ------------------------------------------------------------------ scaling with molecule size
def analytic_scaling(gl, scenes: list[tuple[str, int, Scene]], repeats: int) -> list[dict]:
    variants = (
        ("analytic_ms", replace(BASE, mode="analytic", k=16)),
        ("analytic32_ms", replace(BASE, mode="analytic", k=32)),
        ("ssao_ms", replace(BASE, mode="ssao")),
        ("rt1_ms", replace(BASE, mode="rt", rt_spp=1, blur=False)),
    )
    passes = [AmbientOcclusion(scene.grid) for _, _, scene in scenes]
    calls = {
        (i, label): (lambda ao=ao, scene=scene, s=settings: one_frame(ao, scene, s))
        for i, ((_, _, scene), ao) in enumerate(zip(scenes, passes))
        for label, settings in variants
    }
    seconds = interleaved_times(gl, calls, repeats)
    rows = []
    for i, (name, atoms, scene) in enumerate(scenes):
        rows.append(
            {
                "structure": name,
                "atoms": atoms,
                "coverage": scene.coverage,
                **{label: seconds[(i, label)] * 1e3 for label, _ in variants},
            }
        )
    for ao in passes:
        ao.release()
    return rows


def scaling_chart(rows: list[dict], path):
    title = "AO cost vs molecule size at equal screen coverage"
    return cost_vs_size_chart(rows, SCALING_SERIES, title, "time per frame (ms)", path)


# ------------------------------------------------------------------ SSAO and distant occluders
def floor_with_ball(height: float, with_ball: bool = True):
    """A flat sheet of carbon-sized spheres (z = 0) and a 5 Å ball hovering `height` Å above
    its surface (gap between the sheet's top and the ball's bottom)."""
    step = 2.6
    xs = (np.arange(36) - 17.5) * step
    gx, gy = np.meshgrid(xs, xs)
    centers = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    radii = np.full(centers.shape[0], 1.7)
    if with_ball:
        centers = np.vstack([centers, [0.0, 0.0, 1.7 + height + 5.0]])
        radii = np.append(radii, 5.0)
    return centers, radii


def distant_occluders(gl, heights, size, ref_spp: int) -> list[dict]:
    """Occlusion the hovering ball casts on the sheet under it, as each method sees it:
    AO(sheet alone) − AO(sheet + ball), averaged over sheet pixels within 6 Å of the
    ball's axis. The reference rays reach 40 Å."""
    view, proj = oblique_camera((0.0, 0.0, 0.0), 70.0, 50.0, size, fov=35.0)
    candidates = [
        ("reference (40 Å rays)", None),
        ("analytic K=32", replace(BASE, mode="analytic")),
        ("SSAO point 4 Å", replace(BASE, mode="ssao")),
        ("SSAO line 4 Å", replace(BASE, mode="ssao", ssao_sampling="line")),
        ("SSAO point 8 Å", replace(BASE, mode="ssao", ssao_radius=8.0)),
        ("RT 64 spp, 8 Å rays", replace(BASE, mode="rt", rt_spp=64)),
    ]
    rows = []
    for height in heights:
        seen = {}
        for with_ball in (False, True):
            grid = spheres_grid(gl, *floor_with_ball(height, with_ball))
            scene = trace_scene(grid, view, proj, size)
            pos = scene.gbuffer.download()[0]
            under = (
                (scene.atom >= 0)
                & (scene.atom < 36 * 36)
                & (np.hypot(pos[..., 0], pos[..., 1]) < 6.0)
            )
            ao = AmbientOcclusion(grid)
            for label, settings in candidates:
                image = (
                    reference(ao, scene, ref_spp, distance=40.0)
                    if settings is None
                    else read_texture(one_frame(ao, scene, settings))
                )
                seen.setdefault(label, []).append(
                    float(image[under].mean()) if under.any() else float("nan")
                )
            ao.release()
            scene.release()
            grid.release()
        rows.append({"height": height, **{label: a - b for label, (a, b) in seen.items()}})
    return rows


def distant_chart(rows: list[dict], path):
    fig, ax = figure()
    heights = [r["height"] for r in rows]
    for label in [k for k in rows[0] if k != "height"]:
        style = "k-" if label.startswith("reference") else "o--"
        ax.plot(heights, [r[label] for r in rows], style, label=label, lw=2 if style == "k-" else 1)
    ax.set_xlabel("gap between sheet and ball (Å)")
    ax.set_ylabel("occlusion the ball casts (AO drop)")
    ax.set_title("Occluders beyond the sampling radius are missed")
    ax.legend(fontsize=7)
    return save(fig, path)
