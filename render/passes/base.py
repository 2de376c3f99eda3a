"""What every pass sees of a frame (Frame), and what every pass is (Pass)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sasprobe.render.camera import Camera
from sasprobe.render.frame_cache import atoms_rect, intersect_rect, sphere_rect
from sasprobe.render.gl.buffers import MoleculeBuffers
from sasprobe.render.gl.programs import ProgramCache
from sasprobe.render.gl.targets import RenderTargets
from sasprobe.render.gl.uniforms import gl_bytes
from sasprobe.render.scene_state import NavCube, SceneState


WHOLE = "whole"  # ProbeLighting.changed: the whole picture


@dataclass
class ProbeLightTrace:
    """The probe light's shadow rays for the shading pass to trace itself, per pixel
    (shaders/shading_traced.frag): the ShadowPass whose buffers it binds, and the program's
    cases (#defines) and uniforms (ShadowPass.prepared; the grid's are added)."""

    shadows: object
    cases: tuple
    uniforms: dict


@dataclass
class ProbeLighting:
    """What the lighting hands the shading pass about the probe (render/passes/lighting.py):
    the probe light's visibility, as a texture (r32f: from the occlusion atlas) or as rays
    for the shading to trace (`traced`), neither when it is unshadowed; on layered frames,
    the uniforms of the probe's share of the sun and the ambient light
    (shaders/probe_share.glsl) and where its terms changed the picture this frame (besides
    the probe's reach, which the shading pass adds itself), and of that where they changed
    the background's (the probe's pixels and the halos around them: the background shows
    nothing else of the lighting)."""

    visibility: object = None
    share: dict = field(default_factory=dict)
    changed: object = None  # layered frames: the rectangle the lighting's terms changed this frame, or WHOLE
    traced: ProbeLightTrace | None = None
    background_changed: object = None  # layered frames: the part of `changed` the background shows, or WHOLE


@dataclass
class Frame:
    """Everything one frame's passes read; built by the renderer, never kept across frames."""

    ctx: object
    programs: ProgramCache
    targets: RenderTargets
    buffers: MoleculeBuffers
    scene: SceneState
    camera: Camera
    view: np.ndarray  # 4x4 float64
    proj: np.ndarray  # 4x4 float64
    planes: np.ndarray  # N x 4: user planes (+ probe plane) in effect
    cube: NavCube | None  # the navigation cube in effect
    output_fbo: object  # where the final image goes
    light_direction: np.ndarray  # where the directional light travels (molecule frame), for this camera
    index: int = 0  # frame number
    cache: object = None  # the renderer's MoleculeCache (render/frame_cache.py), None when it redraws all
    cached: bool = False  # the molecule layer of the last frame holds: its passes do not run
    probe_lighting: ProbeLighting = field(default_factory=ProbeLighting)  # the lighting's, for the shading pass
    # What of the lit picture differs from the last frame's, for the FXAA pass to redo only
    # that: WHOLE, a rectangle or None, as the shading pass (and a path-traced frame) leave
    # it — its surfaces within `lit_changed`, its background within `lit_background_changed`;
    # and the rectangle the probe's cues drew over it this frame (ProbeCuesPass).
    lit_changed: object = WHOLE
    lit_background_changed: object = WHOLE
    overlay: object = None
    # What several passes ask of the frame, found once (the camera and the probe hold
    # still within a frame): the view-projection, the camera's basis, the probe's rectangles.
    _found: dict = field(default_factory=dict, repr=False)

    @property
    def size(self) -> tuple[int, int]:
        return self.targets.size

    @property
    def viewproj(self) -> np.ndarray:
        if "viewproj" not in self._found:
            self._found["viewproj"] = self.proj @ self.view
        return self._found["viewproj"]

    def camera_basis(self) -> np.ndarray:
        if "basis" not in self._found:
            self._found["basis"] = self.camera.basis()
        return self._found["basis"]

    def probe_rect(self, radius: float | None = None):
        """Pixels the probe (or a sphere of `radius` around its centre) can cover; None without a probe."""
        probe = self.scene.probe
        if probe is None:
            return None
        radius = probe.radius if radius is None else float(radius)
        key = ("probe_rect", radius, probe.center.tobytes())
        if key not in self._found:
            self._found[key] = sphere_rect(probe.center, radius, self.viewproj, self.size)
        return self._found[key]

    def reach_rect(self, radius: float):
        """A rectangle holding the molecule's pixels within `radius` of the probe's centre:
        what the probe's light and its share of the AO can change (its own pixels aside)."""
        return intersect_rect(self.probe_rect(radius), self.molecule_rect())

    def molecule_rect(self):
        """Pixels the molecule layer can cover: every atom's sphere (culled ones too: the
        backbone trace runs through them), once per molecule layer (render/frame_cache.py)."""
        cache = self.cache
        if cache is not None and cache.layer_rect is not None:
            return cache.layer_rect[0]
        structure = self.scene.structure
        radius = float(structure.vdw_radii.max(initial=0.0))
        rect = atoms_rect(structure.positions, radius, self.viewproj, self.size)
        if cache is not None:
            cache.layer_rect = (rect,)
        return rect

    def near_plane(self) -> np.ndarray:
        """The camera's near plane as a clip plane (spheres crossing it get a cap)."""
        forward = -self.camera_basis()[:, 2]
        return np.array([*forward, -float(forward @ self.camera.eye) - self.camera.near])

    def raster_camera_uniforms(self) -> dict:
        """The camera as the impostor and line shaders take it (shaders/camera.glsl)."""
        p = self.proj
        w, h = self.size
        return {
            "u_viewproj": gl_bytes(self.viewproj),
            "u_eye": tuple(float(v) for v in self.camera.eye),
            "u_cam_basis": np.ascontiguousarray(self.camera_basis().T, dtype=np.float32).tobytes(),
            "u_ray_scale": (1.0 / p[0, 0], 1.0 / p[1, 1], float(p[0, 2]), float(p[1, 2])),
            "u_viewport": (0.0, 0.0, float(w), float(h)),
        }


MOLECULE, FRAME = "molecule", "frame"  # Pass.layer


class Pass:
    """Base of the passes: on by default, no G-buffer export layers, nothing to release.

    `layer` MOLECULE: the pass draws the molecule layer (what does not depend on the probe)
    and does not run while that layer is cached (Frame.cached). `state()` is what of the
    pass's own configuration shapes the picture; it is part of the molecule layer's key
    (render/frame_cache.py), so a setting added to a pass's `settings` dataclass is keyed
    without being listed."""

    name = "pass"
    layer = FRAME

    def state(self):
        return getattr(self, "settings", None)

    def enabled(self, frame: Frame) -> bool:
        return True

    def run(self, frame: Frame) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def gbuffer_layers(self, frame: Frame) -> dict[str, np.ndarray]:
        """Extra layers this pass adds to the G-buffer export (render/gbuffer_export.py)."""
        return {}

    def release(self) -> None:
        pass
