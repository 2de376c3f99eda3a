"""Uniform plumbing shared by every program: values, matrices and the clip-plane array."""

from __future__ import annotations

import numpy as np

MAX_CLIP_PLANES = 24  # the shaders' u_planes / u_clip_planes arrays (generated constants.glsl)


def gl_bytes(matrix: np.ndarray) -> bytes:
    """Column-major float32 bytes of a (column-vector) matrix, as GL uniforms expect."""
    return np.ascontiguousarray(np.asarray(matrix, dtype=np.float32).T).tobytes()


def view_proj_uniforms(view: np.ndarray, proj: np.ndarray) -> dict:
    """u_view and u_proj of the screen-space compute passes (SSAO, blur, edge cueing)."""
    return {"u_view": gl_bytes(view), "u_proj": gl_bytes(proj)}


def apply_uniforms(prog, values: dict) -> None:
    """Set uniforms (bytes are written raw: matrices); unused names are skipped. Looked up
    with Program.get: `name in prog` walks every member of the program."""
    for name, value in values.items():
        member = prog.get(name, None)
        if member is None:
            continue
        if isinstance(value, bytes):
            member.write(value)
        else:
            member.value = value


def padded_planes(planes: np.ndarray) -> np.ndarray:
    """N x 4 planes as the shaders' MAX_CLIP_PLANES x 4 float32 array; ValueError beyond it."""
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 4)
    if planes.shape[0] > MAX_CLIP_PLANES:
        raise ValueError(
            f"at most {MAX_CLIP_PLANES} clip planes reach the shaders, got {planes.shape[0]}"
        )
    padded = np.zeros((MAX_CLIP_PLANES, 4), dtype=np.float32)
    padded[: planes.shape[0]] = planes
    return padded


def apply_planes(prog, planes: np.ndarray) -> None:
    padded = padded_planes(planes)
    count = int(np.asarray(planes).size // 4)
    apply_uniforms(prog, {"u_n_planes": count, **({"u_planes": padded.tobytes()} if count else {})})
