"""What every pass sees of a frame, and the helpers they share."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sasprobe.render.camera import Camera, gl_bytes
from sasprobe.render.scene import NavCube, SceneState
from sasprobe.render.shaders import ProgramCache
from sasprobe.render.targets import RenderTargets
from sasprobe.render.buffers import MoleculeBuffers

MAX_CLIP_PLANES = 24  # shaders/clip.glsl


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
    index: int = 0  # frame number

    @property
    def size(self) -> tuple[int, int]:
        return self.targets.size

    @property
    def viewproj(self) -> np.ndarray:
        return self.proj @ self.view

    def near_plane(self) -> np.ndarray:
        """The camera's near plane as a clip plane (spheres crossing it get a cap)."""
        forward = -self.camera.basis()[:, 2]
        return np.array([*forward, -float(forward @ self.camera.eye) - self.camera.near])

    def camera_uniforms(self) -> dict:
        p = self.proj
        w, h = self.size
        return {
            "u_viewproj": gl_bytes(self.viewproj),
            "u_eye": tuple(float(v) for v in self.camera.eye),
            "u_cam_basis": np.ascontiguousarray(self.camera.basis().T, dtype=np.float32).tobytes(),
            "u_ray_scale": (1.0 / p[0, 0], 1.0 / p[1, 1], float(p[0, 2]), float(p[1, 2])),
            "u_viewport": (0.0, 0.0, float(w), float(h)),
        }


def apply_uniforms(prog, values: dict) -> None:
    """Set uniforms (bytes are written raw: matrices); unused names are skipped."""
    for name, value in values.items():
        if name not in prog:
            continue
        if isinstance(value, bytes):
            prog[name].write(value)
        else:
            prog[name].value = value


def apply_planes(prog, planes: np.ndarray) -> None:
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 4)
    if planes.shape[0] > MAX_CLIP_PLANES:
        raise ValueError(f"at most {MAX_CLIP_PLANES} planes reach the shaders, got {planes.shape[0]}")
    if "u_n_planes" in prog:
        prog["u_n_planes"].value = int(planes.shape[0])
    if "u_planes" in prog and planes.shape[0]:
        padded = np.zeros((MAX_CLIP_PLANES, 4), dtype=np.float32)
        padded[: planes.shape[0]] = planes
        prog["u_planes"].write(padded.tobytes())


class Pass:
    """Base of the passes: on by default, nothing to release."""

    name = "pass"

    def enabled(self, frame: Frame) -> bool:
        return True

    def run(self, frame: Frame) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def release(self) -> None:
        pass


class ClearPass(Pass):
    """Background values in the G-buffer (depth 1, atom id -1) and visibility 1."""

    name = "clear"

    def __init__(self, ctx, programs: ProgramCache):
        self.prog = programs.get("fullscreen.vert", "gbuffer_clear.frag")
        self.vao = ctx.vertex_array(self.prog, [])

    def run(self, frame: Frame) -> None:
        t = frame.targets
        t.gbuffer_fbo.use()
        t.gbuffer_fbo.clear(depth=1.0)
        frame.ctx.disable(frame.ctx.DEPTH_TEST | frame.ctx.BLEND)
        self.vao.render(frame.ctx.TRIANGLES, vertices=3)
        t.clear_visibility()

    def release(self) -> None:
        self.vao.release()

