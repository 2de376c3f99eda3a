"""The lighting options of `sasprobe render` (--shadows, --ao and its methods' settings,
--edges, --path-trace, --samples, --probe-light-range) and the LightingSettings they make
on top of the chosen preset. Every default shown in a help text is read from the settings
dataclass that holds it."""

from __future__ import annotations

import argparse
import math
from dataclasses import replace

from sasprobe.cli.argtypes import positive_float, positive_int
from sasprobe.common.errors import UserError


def _shell(text: str) -> tuple[float, float]:
    try:
        inner, outer = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"'{text}' is not INNER,OUTER (Å, e.g. -0.4,0.8)"
        ) from None
    if not (math.isfinite(inner) and math.isfinite(outer)) or outer < inner:
        raise argparse.ArgumentTypeError(
            f"'{text}': the outer offset must be finite and at least the inner one"
        )
    return inner, outer


def add_lighting_arguments(parser: argparse.ArgumentParser) -> None:
    from sasprobe.render.lighting.settings import (
        ANALYTIC_K,
        AO_MODES,
        DEFAULT_PROBE_RANGE,
        EDGE_MODES,
        HEADLESS_SAMPLES,
        MAX_BOUNCES,
        SHADOW_MODES,
        SSAO_SAMPLING,
        LightingSettings,
        PathTracing,
    )

    base = LightingSettings()
    ao, soft, tracer = base.ao, base.soft, PathTracing()
    g = parser.add_argument_group(
        "lighting (OpenGL 4.3; the window's S, V, A, Shift+A, E, G keys switch them; "
        "defaults are the default preset's, --preset changes them)"
    )
    g.add_argument(
        "--shadows",
        choices=SHADOW_MODES,
        default=None,
        help="shadows of the directional and the probe light, traced through the grid; "
        "precomputed: "
        f"the directional light's hard shadows from per-atom patches (for a light fixed in the "
        f"molecule frame) (default {base.shadows})",
    )
    g.add_argument(
        "--soft-shell",
        type=_shell,
        default=None,
        metavar="INNER,OUTER",
        help=f"soft shadows: Parker shell around each atom, Å from its vdW radius "
        f"(default {soft.inner:g},{soft.outer:g})",
    )
    g.add_argument(
        "--soft-growth",
        type=float,
        default=None,
        metavar="Å",
        help=f"soft shadows: distance over which penumbrae reach full width "
        f"(default {soft.growth:g}; 0 = everywhere)",
    )
    g.add_argument(
        "--ao", choices=AO_MODES, default=None, help=f"ambient occlusion method (default {ao.mode})"
    )
    g.add_argument(
        "--ao-k",
        type=int,
        choices=ANALYTIC_K,
        default=None,
        help=f"analytic AO: neighbours per atom (default {ao.k})",
    )
    g.add_argument(
        "--ao-distance",
        type=positive_float,
        default=None,
        metavar="Å",
        help=f"ray-traced AO: ray length (default {ao.distance:g})",
    )
    g.add_argument(
        "--ao-spp",
        type=positive_int,
        default=None,
        metavar="N",
        help=f"ray-traced AO: samples per pixel per frame (default {ao.rt_spp})",
    )
    g.add_argument(
        "--no-ao-blur", action="store_true", help="ray-traced AO and SSAO: no bilateral blur"
    )
    g.add_argument(
        "--ao-patch",
        type=positive_int,
        default=None,
        metavar="N",
        help=f"precomputed AO and shadows: texels per atom patch side (default {ao.patch}; "
        "QuteMol: 1024-4096 texture side / ceil(sqrt(atoms)), 16 for 1AON)",
    )
    g.add_argument(
        "--ao-directions",
        type=positive_int,
        default=None,
        metavar="N",
        help=f"precomputed AO: ray directions per texel (default {ao.directions}; QuteMol: 128)",
    )
    g.add_argument(
        "--ssao-radius",
        type=positive_float,
        default=None,
        metavar="Å",
        help=f"SSAO sampling radius (default {ao.ssao_radius:g})",
    )
    g.add_argument(
        "--ssao-intensity",
        type=positive_float,
        default=None,
        help=f"SSAO intensity (default {ao.ssao_intensity:g})",
    )
    g.add_argument(
        "--ssao-sampling",
        choices=SSAO_SAMPLING,
        default=None,
        help=f"SSAO: point or line samples (default {ao.ssao_sampling})",
    )
    g.add_argument(
        "--ssao-half", action="store_true", help="SSAO at half resolution (blurred back up)"
    )
    g.add_argument(
        "--edges",
        choices=EDGE_MODES,
        default=None,
        help=f"QuteMol edge cueing: depth-aware contour lines, halos, both (default {base.edges})",
    )
    g.add_argument(
        "--path-trace",
        action="store_true",
        help="progressive path tracing instead of the shading pass",
    )
    g.add_argument(
        "--pt-bounces",
        type=int,
        choices=range(MAX_BOUNCES + 1),
        default=None,
        help=f"path bounces (default {tracer.bounces})",
    )
    g.add_argument(
        "--pt-spp",
        type=positive_int,
        default=None,
        metavar="N",
        help=f"path samples per pixel per frame (default {tracer.spp})",
    )
    g.add_argument(
        "--samples",
        type=int,
        default=None,
        metavar="N",
        help=f"progressive effects accumulate N samples per pixel before each frame is shown "
        f"(headless default: {HEADLESS_SAMPLES['reference']} for --ao reference, "
        f"{HEADLESS_SAMPLES['path_tracing']} with --path-trace)",
    )
    g.add_argument(
        "--probe-light-range",
        type=positive_float,
        default=None,
        metavar="Å",
        help=f"the probe light's reach (default {DEFAULT_PROBE_RANGE:g})",
    )


def lighting_from_args(args, headless: bool):
    """(LightingSettings, explicit): the preset's lighting with the flags' changes; explicit
    when the user asked for a lighting effect (or a preset), so that a driver without
    OpenGL 4.3 is an error rather than a warning.

    A headless still waits for its progressive effects to converge (HEADLESS_SAMPLES); a
    video following a live daemon does not (it would film a few pictures, each repeated
    until the next was done): its frames accumulate while the picture holds, as a
    window's do."""
    from sasprobe.render.lighting.presets import DEFAULT_PRESET, PRESETS, headless_samples
    from sasprobe.render.lighting.settings import HEADLESS_SAMPLES, PathTracing

    base = PRESETS[args.preset].lighting
    ao = base.ao
    try:
        ao = replace(
            ao,
            **{
                k: v
                for k, v in {
                    "mode": args.ao,
                    "k": args.ao_k,
                    "distance": args.ao_distance,
                    "rt_spp": args.ao_spp,
                    "patch": args.ao_patch,
                    "directions": args.ao_directions,
                    "ssao_radius": args.ssao_radius,
                    "ssao_intensity": args.ssao_intensity,
                    "ssao_sampling": args.ssao_sampling,
                }.items()
                if v is not None
            },
        )
        ao = replace(ao, blur=not args.no_ao_blur, ssao_half_resolution=args.ssao_half)
        soft = base.soft
        if args.soft_shell is not None:
            soft = replace(soft, inner=args.soft_shell[0], outer=args.soft_shell[1])
        if args.soft_growth is not None:
            soft = replace(soft, growth=max(0.0, args.soft_growth))
        tracer = replace(
            PathTracing(),
            **{
                k: v
                for k, v in {"bounces": args.pt_bounces, "spp": args.pt_spp}.items()
                if v is not None
            },
        )
        settings = replace(
            base,
            shadows=args.shadows or base.shadows,
            soft=soft,
            ao=ao,
            edges=args.edges or base.edges,
            path_tracing=args.path_trace,
            path_tracer=tracer,
        )
        samples = args.samples
        live_video = args.connect is not None and (args.seconds or (args.frames or 1) > 1)
        if samples is None and live_video:
            samples = 0
        elif samples is None:
            samples = 0
            if headless and args.path_trace:
                samples = HEADLESS_SAMPLES["path_tracing"]
            elif headless and ao.mode == "reference":
                samples = HEADLESS_SAMPLES["reference"]
            elif headless:
                samples = headless_samples(settings)
        settings = replace(settings, samples=samples)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    explicit = (
        args.shadows not in (None, "off")
        or args.ao not in (None, "off")
        or args.path_trace
        or args.edges not in (None, "off")
        or args.preset != DEFAULT_PRESET
    )
    return settings, explicit
