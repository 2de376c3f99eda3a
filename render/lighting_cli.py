"""`sasprobe render`'s lighting options: shadows, ambient occlusion, edge cueing, path
tracing, and the LightingSettings they make."""

from __future__ import annotations

import argparse
import math
from dataclasses import replace

from sasprobe.errors import UserError
from sasprobe.render.lighting_params import (
    ANALYTIC_K,
    AO_MODES,
    EDGE_MODES,
    MAX_BOUNCES,
    SHADOW_MODES,
    SSAO_SAMPLING,
    LightingSettings,
    PathTracing,
)
from sasprobe.units import positive_float, positive_int

HEADLESS_SAMPLES = {"reference": 256, "path_tracing": 64}  # per pixel before a headless frame is written


def _shell(text: str) -> tuple[float, float]:
    try:
        inner, outer = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not INNER,OUTER (Å, e.g. -0.4,0.8)") from None
    if not (math.isfinite(inner) and math.isfinite(outer)) or outer < inner:
        raise argparse.ArgumentTypeError(f"'{text}': the outer offset must be finite and at least the inner one")
    return inner, outer


def add_lighting_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("lighting (OpenGL 4.3; the window's S, V, A, C, E, G keys switch them)")
    g.add_argument("--shadows", choices=SHADOW_MODES, default=None,
                   help="shadows of the directional and the probe light, traced through the grid (default hard)")
    g.add_argument("--soft-shell", type=_shell, default=None, metavar="INNER,OUTER",
                   help="soft shadows: Parker shell around each atom, Å from its vdW radius (default -0.4,0.8)")
    g.add_argument("--soft-growth", type=float, default=None, metavar="Å",
                   help="soft shadows: distance over which penumbrae reach full width (default 4; 0 = everywhere)")
    g.add_argument("--ao", choices=AO_MODES, default=None, help="ambient occlusion method (default analytic)")
    g.add_argument("--ao-k", type=int, choices=ANALYTIC_K, default=None, help="analytic AO: neighbours per atom (32)")
    g.add_argument("--ao-distance", type=positive_float, default=None, metavar="Å",
                   help="ray-traced AO: ray length (default 8)")
    g.add_argument("--ao-spp", type=positive_int, default=None, metavar="N", help="ray-traced AO: samples per pixel per frame (1)")
    g.add_argument("--no-ao-blur", action="store_true", help="ray-traced AO and SSAO: no bilateral blur")
    g.add_argument("--ssao-radius", type=positive_float, default=None, metavar="Å", help="SSAO sampling radius (4)")
    g.add_argument("--ssao-intensity", type=positive_float, default=None, help="SSAO intensity (2)")
    g.add_argument("--ssao-sampling", choices=SSAO_SAMPLING, default=None, help="SSAO: point or line samples (point)")
    g.add_argument("--ssao-half", action="store_true", help="SSAO at half resolution (blurred back up)")
    g.add_argument("--edges", choices=EDGE_MODES, default=None,
                   help="QuteMol edge cueing: depth-aware contour lines, halos, both (default off)")
    g.add_argument("--path-trace", action="store_true", help="progressive path tracing instead of the light pass")
    g.add_argument("--pt-bounces", type=int, choices=range(MAX_BOUNCES + 1), default=None, help="path bounces (3)")
    g.add_argument("--pt-spp", type=positive_int, default=None, metavar="N", help="path samples per pixel per frame (1)")
    g.add_argument("--samples", type=int, default=None, metavar="N",
                   help="progressive effects accumulate N samples per pixel before each frame is shown "
                        "(headless default: 256 for --ao reference, 64 with --path-trace)")
    g.add_argument("--probe-light-range", type=positive_float, default=None, metavar="Å",
                   help="the probe light's reach (default 20)")


def lighting_from_args(args, headless: bool) -> tuple[LightingSettings, bool]:
    """(settings, explicit): explicit when the user asked for a lighting effect, so that a
    driver without OpenGL 4.3 is an error rather than a warning."""
    base = LightingSettings()
    ao = base.ao
    try:
        ao = replace(ao, **{k: v for k, v in {
            "mode": args.ao, "k": args.ao_k, "distance": args.ao_distance, "rt_spp": args.ao_spp,
            "ssao_radius": args.ssao_radius, "ssao_intensity": args.ssao_intensity, "ssao_sampling": args.ssao_sampling,
        }.items() if v is not None})
        ao = replace(ao, blur=not args.no_ao_blur, ssao_half_resolution=args.ssao_half)
        soft = base.soft
        if args.soft_shell is not None:
            soft = replace(soft, inner=args.soft_shell[0], outer=args.soft_shell[1])
        if args.soft_growth is not None:
            soft = replace(soft, growth=max(0.0, args.soft_growth))
        tracer = replace(PathTracing(), **{k: v for k, v in {"bounces": args.pt_bounces, "spp": args.pt_spp}.items()
                                           if v is not None})
        samples = args.samples
        if samples is None:
            samples = 0
            if headless and args.path_trace:
                samples = HEADLESS_SAMPLES["path_tracing"]
            elif headless and ao.mode == "reference":
                samples = HEADLESS_SAMPLES["reference"]
        settings = LightingSettings(
            shadows=args.shadows or base.shadows, soft=soft, ao=ao, edges=args.edges or base.edges,
            path_tracing=args.path_trace, path_tracer=tracer, samples=samples,
        )
    except ValueError as exc:
        raise UserError(str(exc)) from None
    explicit = (args.shadows not in (None, "off") or args.ao not in (None, "off") or args.path_trace
                or args.edges not in (None, "off"))
    return settings, explicit


def check_soft_shell(settings: LightingSettings, probe_radius: float) -> None:
    """The grid holds each sphere expanded by the probe radius: a thicker soft shell would
    be cut at cell borders."""
    if settings.soft.outer > probe_radius + 1e-9:
        raise UserError(f"--soft-shell outer offset {settings.soft.outer:g} Å exceeds the probe radius "
                        f"{probe_radius:g} Å (the grid's expansion)")
