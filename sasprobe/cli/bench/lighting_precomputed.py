"""QuteMol's precomputed occlusion in `sasprobe bench lighting`: its bake time against
molecule size (every reference structure whole, and a ~300-atom navigation cube of the
largest), and how the patch resolution trades the directional shadow's boundary accuracy
(against the exact per-pixel shadow traced through the grid) for bake time and lookup
time. Its place on the AO speed-vs-error chart is in bench/lighting_ao.py."""

from __future__ import annotations

import numpy as np

from sasprobe.cli.bench.charts import figure, save
from sasprobe.cli.bench.lighting_scene import Scene, interleaved_times
from sasprobe.molecule import DEFAULT_PROBE_RADIUS
from sasprobe.render.gl.textures import read_texture
from sasprobe.render.lighting.ao.precomputed import OcclusionAtlas
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.settings import HARD_SHADOW, AOSettings, DirectionalLight
from sasprobe.render.lighting.shadows import ShadowTracer
from sasprobe.render.lighting.uploaded_grid import UploadedGrid

DEFAULT = AOSettings()
SUN = np.array([0.45, 0.8, 0.4]) / np.linalg.norm([0.45, 0.8, 0.4])  # towards the light


CUBE_BAKES = 5  # a cube's bake takes tens of milliseconds: the median of a few
# Structures below SMALL_ATOMS whole: the median of a few bakes too
SMALL_BAKES, SMALL_ATOMS = (
    3,
    20_000,
)


def bake_seconds(
    grid: UploadedGrid,
    culling: Culling,
    settings: AOSettings = DEFAULT,
    sun: bool = True,
    repeats: int = 1,
) -> dict:
    """Bakes for `culling`, its programs compiled first on a few atoms (as a renderer's are
    after its first bake): `total_s`, the accessibility and the light channel in one bake
    (what a culling change costs the renderer with both precomputed); `ambient_s`, the
    accessibility alone (--ao precomputed with traced shadows); `sun_s`, the light channel
    alone (what the light moving costs). With `repeats`, the medians of that many, each a
    bake anew: a cube moved 0.01 Å between them (as when it drifts), a whole structure's
    culling set again."""
    atlas = OcclusionAtlas(grid)

    def bake(light: bool) -> float:
        if not atlas.update(
            settings.patch,
            settings.directions,
            settings.distance,
            ambient=True,
            sun_direction=SUN if light else None,
        ):
            # A stale time would be reported
            raise RuntimeError("bake_seconds: the atlas had nothing to bake")
        return atlas.bake_seconds

    def bake_round(c: Culling) -> tuple[float | None, float, float | None]:
        """Both channels after a culling change, the accessibility alone after another (the
        same culling set again: a new version, so the atlas is baked anew), then the light
        alone (the accessibility holds)."""
        both = light = None
        if sun:
            grid.set_culling(c)
            both = bake(True)
        grid.set_culling(c)
        ambient = bake(False)
        if sun:
            light = bake(True)
        return both, ambient, light

    try:
        # Each kind of bake's programs compiled first
        bake_round(Culling(nav_cube=(grid.grid.centers[0], 2.0)))
        rounds = []
        for k in range(repeats):
            moved = (
                culling
                if culling.nav_cube is None
                else Culling(
                    culling.clip_planes, (culling.nav_cube[0] + 0.01 * k, culling.nav_cube[1])
                )
            )
            rounds.append(bake_round(moved))
        both, ambient, light = ([r[i] for r in rounds if r[i] is not None] for i in range(3))

        def median(values):
            return float(np.median(values)) if values else 0.0

        ambient_s = median(ambient)
        return {
            "patches": atlas.n_slots,
            "ambient_s": ambient_s,
            "sun_s": median(light),
            "total_s": median(both) if sun else ambient_s,
            "overflows": atlas.overflows,
            "bakes": repeats,
        }
    finally:
        atlas.release()


def bake_scaling(gl, structures: list[tuple[str, object]], cube_of) -> list[dict]:
    """Bake times of every structure whole and of a ~300-atom cube of the largest."""
    rows = []
    for sid, structure in structures:
        grid = UploadedGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
        repeats = SMALL_BAKES if structure.n_atoms < SMALL_ATOMS else 1
        rows.append(
            {
                "structure": sid,
                "atoms": structure.n_atoms,
                "cube": False,
                **bake_seconds(grid, Culling(), repeats=repeats),
            }
        )
        grid.release()
    sid, structure = max(structures, key=lambda s: s[1].n_atoms)
    cube, inside = cube_of(structure)
    grid = UploadedGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
    rows.append(
        {
            "structure": f"{sid} cube",
            "atoms": structure.n_atoms,
            "cube": True,
            "atoms_in_cube": inside,
            **bake_seconds(grid, Culling(nav_cube=(cube.center, cube.half)), repeats=CUBE_BAKES),
        }
    )
    grid.release()
    return rows


def patch_sweep(gl, scene: Scene, patches, repeats: int) -> dict:
    """Hard directional shadows from patches of each resolution against the exact per-pixel
    shadow: pixels whose lit/shadowed class differs, the mean absolute difference, bake and
    lookup time; the per-pixel trace's time for comparison."""
    mask = scene.atom >= 0
    sun = DirectionalLight(tuple(SUN))
    shadows = ShadowTracer(scene.grid)
    exact_tex = shadows.trace(scene.gbuffer, sun, HARD_SHADOW)
    exact = read_texture(exact_tex).copy()
    traced_ms = (
        interleaved_times(
            gl, {0: lambda: shadows.trace(scene.gbuffer, sun, HARD_SHADOW, out=exact_tex)}, repeats
        )[0]
        * 1e3
    )
    rows = []
    # One atlas, its programs compiled by a first bake: the bakes are timed warm
    atlas = OcclusionAtlas(scene.grid)
    atlas.update(
        patches[0], DEFAULT.directions, DEFAULT.distance, ambient=False, sun_direction=-SUN
    )
    for patch in patches:
        atlas.update(patch, DEFAULT.directions, DEFAULT.distance, ambient=False, sun_direction=SUN)
        bake_s = atlas.bake_seconds
        baked = read_texture(atlas.lookup(scene.gbuffer, False, SUN)[1])
        lookup_ms = (
            interleaved_times(gl, {0: lambda: atlas.lookup(scene.gbuffer, False, SUN)}, repeats)[0]
            * 1e3
        )
        rows.append(
            {
                "patch": patch,
                "bake_s": bake_s,
                "lookup_ms": lookup_ms,
                "wrong_class": float(((baked >= 0.5) != (exact >= 0.5))[mask].mean()),
                "mean_abs_error": float(np.abs(baked - exact)[mask].mean()),
            }
        )
    atlas.release()
    shadows.release()
    return {"traced_ms": traced_ms, "rows": rows}


# ------------------------------------------------------------------ charts
def scaling_chart(rows: list[dict], path):
    fig, ax = figure()
    whole = [r for r in rows if not r["cube"]]
    ax.loglog(
        [r["atoms"] for r in whole],
        [r["total_s"] for r in whole],
        "o-",
        label="whole structure, both channels in one bake",
    )
    ax.loglog(
        [r["atoms"] for r in whole],
        [r["ambient_s"] for r in whole],
        "s:",
        label="accessibility alone",
    )
    for r in rows:
        if r["cube"]:
            ax.loglog(
                [r["atoms"]],
                [r["total_s"]],
                "D",
                color="tab:red",
                label=f"~300-atom cube of {r['structure'].split()[0]}",
            )
    ax.axhline(3.0, color="0.5", lw=0.8, ls="--", label="target: 1AON whole < 3 s")
    ax.axhline(0.05, color="tab:red", lw=0.8, ls="--", label="target: 300-atom cube < 50 ms")
    ax.set_xlabel("atoms in the structure")
    ax.set_ylabel("bake time (s)")
    ax.set_title(
        f"Precomputed occlusion: bake time ({DEFAULT.patch}x{DEFAULT.patch} texels, "
        f"{DEFAULT.directions} directions)",
        fontsize=9,
    )
    ax.legend(fontsize=7)
    return save(fig, path)


def patch_chart(sweep: dict, path):
    fig, ax = figure()
    rows = sweep["rows"]
    patches = [r["patch"] for r in rows]
    ax.plot(
        patches,
        [100 * r["wrong_class"] for r in rows],
        "o-",
        label="pixels lit/shadowed wrongly (%)",
    )
    ax.plot(
        patches, [100 * r["mean_abs_error"] for r in rows], "s--", label="mean |baked - exact| (%)"
    )
    ax.set_xlabel("patch side (texels)")
    ax.set_ylabel("error against the exact per-pixel shadow (%)")
    right = ax.twinx()
    right.plot(
        patches, [r["bake_s"] * 1e3 for r in rows], "^:", color="tab:green", label="bake (ms)"
    )
    right.plot(
        patches,
        [r["lookup_ms"] for r in rows],
        "v:",
        color="tab:purple",
        label="lookup per frame (ms)",
    )
    right.axhline(
        sweep["traced_ms"],
        color="tab:purple",
        lw=0.8,
        ls="--",
        label="per-pixel trace per frame (ms)",
    )
    right.set_yscale("log")
    right.set_ylabel("time (ms)")
    lines = ax.get_legend_handles_labels()
    more = right.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], fontsize=7, loc="center right")
    ax.set_title(
        "Precomputed hard shadows: patch resolution vs boundary accuracy vs time", fontsize=9
    )
    return save(fig, path)


def markdown(scaling: list[dict], sweep: dict, structure: str, size) -> str:
    lines = [
        f"### Precomputed occlusion: bake time ({DEFAULT.patch}x{DEFAULT.patch} texels, "
        f"{DEFAULT.directions} "
        f"directions, {DEFAULT.distance:g} Å rays; each channel alone, and both in one bake as at "
        "a culling change)",
        "",
        "| structure | atoms | patches | accessibility alone (s) | light alone (s) | both, one "
        "bake (s) | "
        "bakes (median of) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in scaling:
        lines.append(
            f"| {r['structure']} | {r['atoms']} | {r['patches']} | {r['ambient_s']:.3f} | "
            f"{r['sun_s']:.3f} | "
            f"{r['total_s']:.3f} | {r.get('bakes', 1)} |"
        )
    w, h = size
    lines += [
        "",
        f"### Precomputed hard shadows against the exact per-pixel shadow ({structure}, {w}×{h}; "
        "the "
        f"per-pixel trace takes {sweep['traced_ms']:.1f} ms a frame)",
        "",
        "| patch | bake (ms) | lookup (ms / frame) | pixels lit/shadowed wrongly | mean abs. "
        "difference |",
        "|---:|---:|---:|---:|---:|",
    ]
    for r in sweep["rows"]:
        lines.append(
            f"| {r['patch']} | {r['bake_s'] * 1e3:.1f} | {r['lookup_ms']:.2f} | "
            f"{100 * r['wrong_class']:.2f} % | "
            f"{r['mean_abs_error']:.3f} |"
        )
    return "\n".join(lines)
