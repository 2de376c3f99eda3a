"""What every pass sees of a frame (Frame), and what every pass is (Pass)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from sasprobe.render.camera import Camera
from sasprobe.render.frame_planner import FramePlan
from sasprobe.render.gl.buffers import MoleculeBuffers
from sasprobe.render.gl.programs import ProgramCache
from sasprobe.render.gl.targets import RenderTargets
from sasprobe.render.gl.uniforms import gl_bytes
from sasprobe.render.rects import atoms_rect, intersect_rect, sphere_rect, union_rect
from sasprobe.render.scene_state import NavCube, SceneState


@dataclass
class ProbeLightTrace:
    """The probe light's shadow rays for the shading pass to trace itself, per pixel
    (shaders/shading_traced.frag): the ShadowTracer whose buffers it binds, and the program's
    cases (#defines) and uniforms (ShadowTracer.prepared; the grid's are added)."""

    shadows: object
    cases: tuple
    uniforms: dict


@dataclass
class ProbeLighting:
    """What the lighting hands the shading pass about the probe (render/passes/lighting.py):
    the probe light's visibility, as a texture (r32f: from the occlusion atlas) or as rays
    for the shading to trace (`traced`), neither when it is unshadowed; and on layered
    frames the uniforms of the probe's share of the sun and the ambient light
    (shaders/probe_share.glsl)."""

    visibility: object = None
    share: dict = field(default_factory=dict)
    traced: ProbeLightTrace | None = None


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
    # N x 4: the user planes in effect (the trace's: the probe plane cuts atoms only)
    context_planes: np.ndarray
    cube: NavCube | None  # the navigation cube in effect
    output_fbo: object  # where the final image goes
    # Where the directional light travels (molecule frame), for this camera
    light_direction: np.ndarray
    index: int = 0  # frame number
    # What this frame redraws (render/frame_planner.py)
    plan: FramePlan = field(default_factory=FramePlan)
    # The lighting's, for the shading pass
    probe_lighting: ProbeLighting = field(default_factory=ProbeLighting)
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
        """Pixels the probe (or a sphere of `radius` around its centre) can cover; None without
        a probe."""
        probe = self.scene.probe
        if probe is None:
            return None
        radius = probe.radius if radius is None else float(radius)
        key = ("probe_rect", radius, probe.center.tobytes())
        if key not in self._found:
            self._found[key] = sphere_rect(probe.center, radius, self.viewproj, self.size)
        return self._found[key]

    def reach_rect(self, radius: float):
        """A rectangle holding the pixels of the atoms drawn as spheres within `radius` of the
        probe's centre: what the probe's light and its share of the AO can change (its own
        pixels aside; the backbone trace is context, which the probe does not light)."""
        return intersect_rect(self.probe_rect(radius), self.spheres_rect())

    def molecule_rect(self):
        """Pixels the molecule layer can cover: every atom's sphere (culled ones too: the
        backbone trace runs through them), found once per molecule layer."""
        memo = self.plan.layer_memo
        if "molecule_rect" not in memo:
            structure = self.scene.structure
            memo["molecule_rect"] = atoms_rect(
                structure.positions,
                float(structure.vdw_radii.max(initial=0.0)),
                self.viewproj,
                self.size,
            )
        return memo["molecule_rect"]

    def spheres_rect(self):
        """Pixels the atoms drawn as spheres can cover (in the workspace view: the cube's),
        found once per molecule layer."""
        memo = self.plan.layer_memo
        if "spheres_rect" not in memo:
            structure = self.scene.structure
            drawn = self.scene.sphere_selection(self.camera)
            radius = float(structure.vdw_radii[drawn].max(initial=0.0))
            memo["spheres_rect"] = atoms_rect(
                structure.positions[drawn], radius, self.viewproj, self.size
            )
        return memo["spheres_rect"]

    def lighting_rect(self):
        """Where the lighting has work: the atoms drawn as spheres and the probe (elsewhere the
        picture shows only the backbone trace, which is context, and the background)."""
        return union_rect(self.spheres_rect(), self.probe_rect())

    def terms_rect(self):
        """Where the lighting computes the atoms' terms (1 elsewhere): lighting_rect, empty
        rather than None when nothing is there, since the tracers read None as everywhere."""
        return self.lighting_rect() or (0, 0, 0, 0)

    def compose_rect(self):
        """Where the lighting composes the visibility buffer: terms_rect, or with edge cueing
        (which darkens the trace and the background too) the whole frame."""
        if self.scene.effects.edge_cueing:
            return (0, 0, *self.size)
        return self.terms_rect()

    def near_plane(self) -> np.ndarray:
        """The camera's near plane as a clip plane (spheres crossing it get a cap)."""
        forward = -self.camera_basis()[:, 2]
        return np.array([*forward, -float(forward @ self.camera.eye) - self.camera.near])

    def raster_camera_uniforms(self) -> dict:
        """The camera as the impostor and line shaders take it (shaders/camera.glsl)."""
        return raster_camera_uniforms(
            self.camera, self.viewproj, self.proj, self.size, self.camera_basis()
        )


def raster_camera_uniforms(
    camera: Camera,
    viewproj: np.ndarray,
    proj: np.ndarray,
    size: tuple[int, int],
    basis: np.ndarray | None = None,
) -> dict:
    """A camera as the impostor and line shaders take it (shaders/camera.glsl)."""
    w, h = size
    basis = camera.basis() if basis is None else basis
    return {
        "u_viewproj": gl_bytes(viewproj),
        "u_eye": tuple(float(v) for v in camera.eye),
        "u_cam_basis": np.ascontiguousarray(basis.T, dtype=np.float32).tobytes(),
        "u_ray_scale": (1.0 / proj[0, 0], 1.0 / proj[1, 1], float(proj[0, 2]), float(proj[1, 2])),
        "u_viewport": (0.0, 0.0, float(w), float(h)),
    }


class Layer(Enum):
    """Which layer a pass draws (Pass.layer), and so on which frames it is skipped."""

    MOLECULE = "molecule"  # the molecule layer: skipped while it is kept
    CONTEXT = "context"  # its part the probe plane does not cut (the trace): kept longer
    EVERY_FRAME = "every frame"  # the probe and what depends on it: never skipped


class Pass:
    """Base of the passes: on by default, no G-buffer export layers, nothing to release.

    `state()` is what of the pass's own configuration shapes the picture; it is part of the
    molecule layer's key (render/frame_planner.py), so a setting added to a pass's
    `settings` dataclass is keyed without being listed. `footprint()` says where the probe
    can change what the pass draws this frame, by name; the planner turns footprints into
    the regions passes redo (FramePlan.region)."""

    name = "pass"
    layer = Layer.EVERY_FRAME

    def state(self):
        return getattr(self, "settings", None)

    def enabled(self, frame: Frame) -> bool:
        return True

    def footprint(self, frame: Frame) -> dict:
        """{name: rectangle, None or EVERYWHERE} of this frame (on layered frames)."""
        return {}

    def run(self, frame: Frame) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def exported_arrays(self, frame: Frame) -> dict[str, np.ndarray]:
        """Arrays this pass adds to the G-buffer export (render/gbuffer_export.py)."""
        return {}

    def release(self) -> None:
        pass
