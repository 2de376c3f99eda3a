"""Lighting presets (`--preset`, the window's I key): how strong each light is, which
lighting effects run and on what background, as one name.

    default       key light with hard shadows, ambient light darkened by analytic AO
    soft          ambient light only, under strong ray-traced ambient occlusion (ChimeraX's
                  "soft": no key or fill light, ambient 1.5 shadowed from 64 directions)
    full          key light with soft shadows plus ambient light under ray-traced AO
                  (ChimeraX's "full": key 0.7, ambient 0.8, shadows and 64-direction AO)
    flat          ambient light only, no shading, black contour lines (ChimeraX's "flat":
                  ambient 1.45, silhouettes on): each atom shows its colour exactly
    illustrative  QuteMol's look (Tarini et al. 2006): strong, far-reaching ambient
                  occlusion, depth-aware contour lines and halos, a white background

ChimeraX's presets are read from its `lighting` command (RBVI/ChimeraX, commit
064ab5d6e2fb8b3d30a15719d56e9e8c78093489, src/bundles/std_commands/src/lighting.py); the
intensities here are ours, scaled to this renderer (its ambient term is accessibility-
weighted and reaches the full colour at 1, where ChimeraX's multishadow needs 1.5).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from sasprobe.render.lighting.settings import (
    AOSettings,
    EdgeCueing,
    LightingSettings,
    ShadingSettings,
)

DARK = ShadingSettings().background
WHITE = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class Preset:
    name: str
    ambient: float
    directional: float  # key light intensity
    specular: float
    ao_power: float  # accessibility ** power darkens the ambient term: > 1 is stronger AO
    lighting: LightingSettings
    background: tuple[float, float, float]

    def shading(self, base: ShadingSettings) -> ShadingSettings:
        """`base` with this preset's light intensities and background."""
        return replace(
            base,
            ambient=self.ambient,
            directional_intensity=self.directional,
            specular=self.specular,
            ao_power=self.ao_power,
            background=self.background,
        )


# Ray-traced AO with rays long enough to darken the grooves between domains and subunits,
# not only the gaps between neighbouring atoms (analytic AO's K nearest neighbours).
SOFT_AO = AOSettings(mode="rt", distance=20.0)
FAR_AO = AOSettings(mode="rt", distance=30.0)
HARD_ANALYTIC = LightingSettings(shadows="hard", ao=AOSettings(mode="analytic"))
FLAT = LightingSettings(
    shadows="off",
    ao=AOSettings(mode="off"),
    edges="lines",
    edge_cueing=EdgeCueing(contours=True, halos=False),
)
ILLUSTRATIVE = LightingSettings(
    shadows="off",
    ao=FAR_AO,
    edges="both",
    edge_cueing=EdgeCueing(contours=True, halos=True, halo_strength=0.5),
)
# A headless frame of the ray-traced presets is written once converged this far.
HEADLESS_AO_SAMPLES = 64

# One row a preset: name, ambient, directional (key light), specular, AO power, lighting,
# background.
PRESETS: dict[str, Preset] = {
    p.name: p
    for p in (
        Preset("default", 0.5, 0.7, 0.25, 1.5, HARD_ANALYTIC, DARK),
        Preset("soft", 1.1, 0.0, 0.0, 2.0, LightingSettings(shadows="off", ao=SOFT_AO), DARK),
        Preset("full", 0.7, 0.6, 0.3, 1.5, LightingSettings(shadows="soft", ao=SOFT_AO), DARK),
        Preset("flat", 1.0, 0.0, 0.0, 1.0, FLAT, DARK),
        Preset("illustrative", 1.15, 0.15, 0.0, 2.5, ILLUSTRATIVE, WHITE),
    )
}
PRESET_NAMES = tuple(PRESETS)
DEFAULT_PRESET = "default"


def headless_samples(lighting: LightingSettings) -> int:
    """Samples per pixel a headless frame waits for with this lighting (ray-traced AO converges)."""
    return HEADLESS_AO_SAMPLES if lighting.ao.mode in ("rt", "hybrid") else 0
