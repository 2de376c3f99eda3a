"""How the picture is lit, as plain data (no GL): the shading pass's own parameters, the
lights, and how each lighting effect (shadows, ambient occlusion, edge cueing, path
tracing) is computed. The passes, the CLI's option defaults and help texts, the CPU
references in the tests and the G-buffer export all read them from here."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from sasprobe.molecule.colors import BACKGROUND, HIGHLIGHT, LIT

# Shadow/AO rays start at p + n * (RAY_EPS_ABS + RAY_EPS_REL * max|p_i|) (Å): a few float32
# spacings at the coordinate's magnitude plus a floor of 1e-3 Å, far below what a pixel
# shows. The source atom is excluded from every query as well, which is exact for convex
# solids; the offset only matters where neighbouring atoms meet.
RAY_EPS_ABS = 1e-3
RAY_EPS_REL = 1e-5


def ray_epsilon(points: np.ndarray) -> np.ndarray:
    """Per-point offset (Å) of the ray origin along the normal."""
    points = np.asarray(points, dtype=np.float64)
    return RAY_EPS_ABS + RAY_EPS_REL * np.max(np.abs(points), axis=-1)


def ray_epsilon_uniforms() -> dict[str, float]:
    return {"u_ray_eps_abs": RAY_EPS_ABS, "u_ray_eps_rel": RAY_EPS_REL}


@dataclass(frozen=True)
class DirectionalLight:
    direction: tuple[float, float, float]  # world frame, pointing *towards* the light
    intensity: float = 1.0  # irradiance on a surface facing it (path tracer)

    def unit(self) -> np.ndarray:
        d = np.asarray(self.direction, dtype=np.float64)
        norm = np.linalg.norm(d)
        if not np.isfinite(norm) or norm == 0:
            raise ValueError("a directional light needs a non-zero direction")
        return d / norm


DEFAULT_PROBE_ATTENUATION = LIT.probe_attenuation
DEFAULT_PROBE_RANGE = LIT.probe_range  # Å: the probe light's reach (lit, and shadowed, inside it)


@dataclass
class ShadingSettings:
    """The shading pass (render/passes/shading.py): deferred Phong of the G-buffer with a
    directional light and the probe's point light."""

    ambient: float = LIT.ambient
    directional_intensity: float = LIT.directional
    probe_intensity: float = LIT.probe
    probe_attenuation: tuple[float, float, float] = DEFAULT_PROBE_ATTENUATION
    # Å: the probe light is windowed to 0 here (shadows are traced inside)
    probe_range: float = DEFAULT_PROBE_RANGE
    shininess: float = LIT.shininess
    specular: float = LIT.specular
    background: tuple[float, float, float] = BACKGROUND
    highlight: tuple[float, float, float] = HIGHLIGHT
    # The ambient term takes accessibility ** ao_power (> 1: stronger occlusion)
    ao_power: float = 1.0


@dataclass(frozen=True)
class PointLight:
    """The probe's light at the probe centre; nothing beyond `radius` Å is lit (or traced)."""

    position: tuple[float, float, float]
    radius: float = DEFAULT_PROBE_RANGE
    intensity: float = 1.0
    # Constant, linear, quadratic.
    attenuation: tuple[float, float, float] = DEFAULT_PROBE_ATTENUATION


def probe_falloff(distance, light: PointLight):
    """The point light's falloff: 1 / (c + l d + q d^2) windowed to 0 at its radius by
    (1 - (d/R)^4)^2 (smooth, so the light's edge is not seen)."""
    d = np.asarray(distance, dtype=np.float64)
    c, lin, q = light.attenuation
    window = np.clip(1.0 - (d / light.radius) ** 4, 0.0, 1.0) ** 2
    return window / (c + lin * d + q * d * d)


def light_uniforms(
    sun: DirectionalLight | None, probe_light: PointLight | None
) -> dict[str, object]:
    """Uniforms of shaders/lights.glsl (a missing light is switched off)."""
    return {
        "u_sun_dir": tuple(sun.unit()) if sun is not None else (0.0, 0.0, 1.0),
        "u_sun_intensity": float(sun.intensity) if sun is not None else 0.0,
        "u_probe_light_on": int(probe_light is not None),
        "u_probe_light_pos": tuple(float(v) for v in probe_light.position)
        if probe_light
        else (0.0, 0.0, 0.0),
        "u_probe_light_radius": float(probe_light.radius) if probe_light else 1.0,
        "u_probe_light_atten": tuple(float(v) for v in probe_light.attenuation)
        if probe_light
        else (1.0, 0.0, 0.0),
        "u_probe_light_intensity": float(probe_light.intensity) if probe_light else 0.0,
    }


@dataclass(frozen=True)
class SoftShadow:
    """Parker et al. (1998) single-ray soft shadows.

    Each occluder gets an inner sphere (vdW radius + inner) and an outer sphere (vdW radius
    + outer); a shadow ray passing at distance b from the centre sees smoothstep(inner,
    outer, b), and the minimum over all occluders is the light's visibility. The shell
    widens linearly from nothing at the receiver to full width `growth` Å along the ray
    (0 = full width everywhere): penumbrae grow with the distance between occluder and
    receiver, and atoms touching the receiver do not darken it. inner == outer == 0 is the
    hard shadow. `outer` may not exceed the grid's expansion (the probe radius), since the
    grid only holds each sphere in the cells its expanded sphere overlaps.
    """

    inner: float = -0.4
    outer: float = 0.8
    growth: float = 4.0

    def shell(self) -> tuple[float, float]:
        return (float(self.inner), float(self.outer))


HARD_SHADOW = SoftShadow(0.0, 0.0, 0.0)


AO_MODES = ("off", "analytic", "ssao", "rt", "hybrid", "reference", "precomputed")
PATCH_RANGE = (3, 64)  # precomputed: texels per patch side
DIRECTION_RANGE = (8, 1024)  # precomputed: ray directions
SSAO_SAMPLING = ("point", "line")
ANALYTIC_K = (8, 16, 32)


@dataclass(frozen=True)
class AOSettings:
    """Ambient occlusion, selectable at run time (see render/lighting/ao/__init__.py)."""

    mode: str = "analytic"
    k: int = 32  # analytic: nearest neighbours per atom (8, 16 or 32)
    distance: float = 8.0  # ray-traced / reference: ray length (Å)
    rt_spp: int = 1  # ray-traced: samples per pixel per frame
    blur: bool = True  # bilateral blur of the noisy estimates (SSAO; ray-traced below 16 spp)
    ssao_radius: float = 4.0  # Å
    # Calibrated against converged ray-traced AO (8 Å rays) on 1OKY, checked on 3SN6: with
    # 4 Å point sampling, intensity 2 halves the error of 1 (sasprobe bench lighting).
    ssao_intensity: float = 2.0
    ssao_sampling: str = "point"
    ssao_samples: int = 16
    ssao_half_resolution: bool = False
    reference_spp: int = 32  # reference: samples per frame ...
    reference_total: int = 1024  # ... until this many have accumulated
    # precomputed (QuteMol's per-atom patches, ao/precomputed.py): texels per patch side and ray
    # directions (QuteMol: 128 directions; its patch side grows with the texture, 16 for 1AON)
    patch: int = 8
    directions: int = 64

    def __post_init__(self) -> None:
        if self.mode not in AO_MODES:
            raise ValueError(f"unknown AO mode '{self.mode}' (one of {', '.join(AO_MODES)})")
        if self.ssao_sampling not in SSAO_SAMPLING:
            raise ValueError(f"unknown SSAO sampling '{self.ssao_sampling}' (point or line)")
        if not 1 <= self.k <= 32:
            raise ValueError("analytic AO uses 1 to 32 neighbours")
        for name in ("distance", "ssao_radius"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive")
        for name in ("rt_spp", "ssao_samples", "reference_spp", "reference_total"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1")
        for name, (lo, hi) in (("patch", PATCH_RANGE), ("directions", DIRECTION_RANGE)):
            if not lo <= getattr(self, name) <= hi:
                raise ValueError(
                    f"precomputed AO uses {lo} to {hi} "
                    f"{'texels a patch side' if name == 'patch' else name}"
                )


@dataclass(frozen=True)
class EdgeCueing:
    contours: bool = True
    halos: bool = False
    line_width: float = 1.5  # pixels
    line_threshold: float = 1.5  # Å of depth jump where lines start (full at twice that)
    halo_radius: float = 8.0  # pixels
    halo_depth: float = 6.0  # Å of depth gap for a full halo
    halo_strength: float = 0.6

    def __post_init__(self) -> None:
        for name in ("line_width", "line_threshold", "halo_radius", "halo_depth"):
            if not getattr(self, name) > 0:
                raise ValueError(f"edge cueing {name} must be positive")
        if not 0.0 <= self.halo_strength <= 1.0:
            raise ValueError("halo strength must lie in [0, 1]")

    def reach_px(self) -> int:
        """How far (pixels) a pixel's factor looks: a change of the G-buffer reaches this far."""
        return int(
            np.ceil(
                max(
                    self.line_width if self.contours else 0.0,
                    self.halo_radius if self.halos else 0.0,
                )
            )
        )


MAX_BOUNCES = 3


@dataclass(frozen=True)
class PathTracing:
    bounces: int = 3
    spp: int = 1  # per frame
    max_samples: int = 4096  # per pixel: a still view stops costing anything beyond this
    sky: tuple[float, float, float] = (0.45, 0.47, 0.5)  # radiance of the environment
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not 0 <= self.bounces <= MAX_BOUNCES:
            raise ValueError(f"path tracing uses 0 to {MAX_BOUNCES} bounces")


# Per pixel before a headless frame is written
HEADLESS_SAMPLES = {
    "reference": 256,
    "path_tracing": 64,
}
# Precomputed: the sun's from the occlusion atlas
SHADOW_MODES = (
    "off",
    "hard",
    "soft",
    "precomputed",
)
EDGE_MODES = ("off", "lines", "halos", "both")


@dataclass(frozen=True)
class LightingSettings:
    """What the renderer's lighting computes (render/passes/lighting.py). The scene's
    Effects switch each effect on and off at run time (window keys); these say how."""

    # Off, hard, soft, precomputed (the initial state of the window's S and V keys)
    shadows: str = "hard"
    soft: SoftShadow = SoftShadow()
    ao: AOSettings = AOSettings()  # mode "off": AO starts switched off (A key; then analytic)
    edges: str = "off"  # off, lines, halos, both
    edge_cueing: EdgeCueing = EdgeCueing(contours=True, halos=True)
    path_tracing: bool = False
    path_tracer: PathTracing = PathTracing()
    # Progressive effects accumulate this many samples per pixel before a frame is shown.
    samples: int = 0

    def __post_init__(self) -> None:
        if self.shadows not in SHADOW_MODES:
            raise ValueError(
                f"unknown shadow mode '{self.shadows}' (one of {', '.join(SHADOW_MODES)})"
            )
        if self.edges not in EDGE_MODES:
            raise ValueError(f"unknown edge cueing '{self.edges}' (one of {', '.join(EDGE_MODES)})")
        if self.samples < 0:
            raise ValueError("samples must not be negative")

    def effects(self) -> dict[str, bool]:
        """Initial values of the scene's lighting switches (render/scene_state.py Effects)."""
        return {
            "shadows": self.shadows != "off",
            "soft_shadows": self.shadows == "soft",
            "ambient_occlusion": self.ao.mode != "off",
            "edge_cueing": self.edges != "off",
            "path_tracing": self.path_tracing,
        }

    def check_soft_shell(self, probe_radius: float) -> None:
        """ValueError when the soft shell is thicker than the grid's expansion (the probe
        radius): it would be cut at cell borders."""
        if self.soft.outer > probe_radius + 1e-9:
            raise ValueError(
                f"soft-shadow outer offset {self.soft.outer:g} Å exceeds the probe radius "
                f"{probe_radius:g} Å (the grid's expansion)"
            )

    def edge_settings(self) -> EdgeCueing:
        """Edge cueing as chosen (both effects when toggled on from 'off')."""
        if self.edges == "off":
            return self.edge_cueing
        return replace(
            self.edge_cueing,
            contours=self.edges in ("lines", "both"),
            halos=self.edges in ("halos", "both"),
        )
