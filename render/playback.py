"""A recorded session drawn again at its recorded timing (`sasprobe replay FILE --video`).

Video frame k stands for the moment t0 + k/fps, where t0 is the first recorded pose;
it shows the newest pose published at or before that moment, with the scene (probe
radius, clip planes, lights, cube) and the structure in force then. Everything comes
from the recording itself (the structure is its attachment), read in one pass in file
order, so a long session needs no more memory than a short one.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from sasprobe.protocol.pose import Pose
from sasprobe.protocol.recording import iter_items, pose_from_record


@dataclass
class RecordedFrame:
    index: int  # frame k stands for the first pose's time + k/fps (recording clock)
    structure_sha256: str  # the structure in force (the scene's)
    # Its name, attached bytes and keep_water (None: not attached)
    structure_file: tuple[str, bytes, bool] | None
    scene: dict  # the scene message in force
    pose: Pose  # the newest pose published at or before that moment


def pose_time_range(path: Path) -> tuple[int, int] | None:
    """First and last pose log time of a recording (ns), None without poses."""
    first = last = None
    for item in iter_items(path, decode=False):
        if item.topic == "pose":
            first = item.log_time if first is None else first
            last = item.log_time
    return None if first is None else (first, last)


def frame_count(time_range: tuple[int, int], fps: float) -> int:
    """Frames at 1/fps steps from the first pose up to and including the last one."""
    first, last = time_range
    return int((last - first) * fps // 1_000_000_000) + 1


def recorded_frames(
    path: Path, fps: float, time_range: tuple[int, int] | None = None
) -> Iterator[RecordedFrame]:
    """The state to draw for every video frame, in order."""
    time_range = time_range or pose_time_range(path)
    if time_range is None:
        return
    t0, n = time_range[0], frame_count(time_range, fps)
    files: dict[str, tuple[str, bytes]] = {}
    keep_water: dict[str, bool] = {}
    k = 0
    scene = pose = None

    def frame() -> RecordedFrame:
        sha = scene["structure"]["sha256"]
        attached = (*files[sha], keep_water.get(sha, False)) if sha in files else None
        return RecordedFrame(k, sha, attached, scene, pose)

    for item in iter_items(path):
        if item.topic == "attachment":
            files[item.data["sha256"]] = (item.data["name"], item.raw)
        elif item.topic == "control" and item.data.get("cmd") in ("start", "load"):
            args = item.data.get("args", {})
            keep_water[args.get("structure_sha256") or args.get("sha256")] = bool(
                args.get("keep_water", False)
            )
        elif item.topic == "scene":
            scene = item.data
        elif item.topic == "pose":
            # Frames due before this pose show the state so far.
            while (
                k < n
                and pose is not None
                and scene is not None
                and t0 + k * 1e9 / fps < item.log_time
            ):
                yield frame()
                k += 1
            pose = pose_from_record(item.data)
    while k < n and pose is not None and scene is not None:
        yield frame()
        k += 1


def render_recording(
    path: Path,
    out: Path,
    fps: float,
    size: tuple[int, int],
    progress: Callable[[int], None] | None = None,
) -> dict:
    """Write the session as a video at its recorded timing; returns frame counts and duration."""
    from sasprobe.molecule import parse_structure
    from sasprobe.protocol.view import view_axes
    from sasprobe.render.app import RenderOptions, build_scene, initial_camera, make_renderer
    from sasprobe.render.follow.messages import apply_pose, apply_scene_message
    from sasprobe.render.gl.context import create_headless_context
    from sasprobe.render.lighting.settings import LightingSettings
    from sasprobe.render.output import FrameWriter
    from sasprobe.render.workspace_view import WORKSPACE, WorkspaceView

    from sasprobe.common.errors import UserError

    time_range = pose_time_range(path)
    if time_range is None:
        raise UserError(f"{path}: no recorded poses to draw")
    # `sasprobe render --connect`'s defaults: the workspace view, lighting included (where the
    # GL driver offers OpenGL 4.3)
    opts = RenderOptions(
        headless=True, size=size, fps=fps, lighting=LightingSettings(), view=WORKSPACE
    )
    view = WorkspaceView(WORKSPACE)
    ctx = create_headless_context()
    writer = FrameWriter(out, None, fps)
    renderer = camera = None
    sha = None
    frames = 0
    try:
        for frame in recorded_frames(path, fps, time_range):
            if frame.structure_sha256 != sha:  # the first structure, or a `load` during the session
                sha = frame.structure_sha256
                if frame.structure_file is None:
                    raise UserError(
                        f"{path}: structure {sha[:12]} is not attached to the recording"
                    )
                name, data, keep_water = frame.structure_file
                structure = parse_structure(
                    data, name=name, source=f"{path}:{name}", keep_water=keep_water
                )
                if renderer is not None:
                    renderer.release()
                scene = build_scene(structure, opts)
                renderer = make_renderer(ctx, scene, size, opts)
                camera = initial_camera(scene, opts)
            scene = renderer.scene
            scene.effects.probe_light = apply_scene_message(scene, frame.scene)
            # The session's colours, as its renderers showed them
            if frame.scene.get("color_scheme"):
                scene.effects.color_scheme = frame.scene["color_scheme"]
            axes = view_axes(frame.scene)
            apply_pose(
                scene, frame.pose, cube_enabled=frame.scene["nav_cube"]["enabled"], axes=axes
            )
            renderer.render(view.camera(scene, size[0] / size[1], axes) or camera)
            writer.write(renderer.read_image())
            frames += 1
            if progress is not None:
                progress(1)
    finally:
        writer.close()
        if renderer is not None:
            renderer.release()
        ctx.release()
    return {
        "video": str(out),
        "frames": frames,
        "fps": fps,
        "size": list(size),
        "duration_s": (time_range[1] - time_range[0]) / 1e9,
    }
