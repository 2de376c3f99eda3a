"""A recorded session drawn again at its recorded timing (`sasprobe replay FILE --video`):
each frame protocol/playback.py samples from the recording, drawn as `render --connect`
would have drawn it."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from sasprobe.protocol.playback import pose_time_range, recorded_frames


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
