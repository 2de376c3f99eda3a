"""What the window offers of the lighting: its status line and the presets it switches
to (render/window/window_app.py's keys), on a renderer with the lighting installed
(render/passes/lighting.py)."""

from __future__ import annotations

from dataclasses import replace


def lighting_status(renderer) -> str:
    """One line for the window's readout: which lighting effects are on, and how far the
    progressive ones have got."""
    lighting = renderer.lighting
    fx = renderer.scene.effects
    parts = []
    if fx.shadows:
        parts.append("soft shadows" if fx.soft_shadows else "hard shadows")
    if fx.ambient_occlusion:
        progressive = lighting.ao_mode in ("rt", "hybrid", "reference") and lighting.ao is not None
        parts.append(
            f"AO {lighting.ao_mode}" + (f" {lighting.ao.samples} spp" if progressive else "")
        )
    if fx.edge_cueing:
        parts.append("edges")
    if fx.path_tracing and lighting.tracer is not None:
        parts.append(f"path tracing {lighting.tracer.samples} spp")
    return "lighting: " + (", ".join(parts) if parts else "off")


def apply_preset(renderer, preset, background=None) -> None:
    """Switch a running renderer to a lighting preset (render/lighting/presets.py): its light
    intensities and background (`background` overrides it) and which effects are on."""
    shading = renderer.pass_named("shading").settings
    for key, value in vars(
        preset.shading(shading)
    ).items():  # in place: the lighting pass shares it
        setattr(shading, key, value)
    if background is not None:
        shading.background = tuple(background)
    lighting = renderer.lighting
    if lighting is None:
        return
    lighting.settings = replace(preset.lighting, samples=lighting.settings.samples)
    if preset.lighting.ao.mode != "off":
        lighting.ao_mode = preset.lighting.ao.mode
    for key, value in preset.lighting.effects().items():
        setattr(renderer.scene.effects, key, value)
