"""`sasprobe render` put together: options -> structure and scene -> context -> loop.

Following a daemon the picture starts in the workspace view (render/workspace_view.py),
with the clip plane at the probe on; standalone it starts in the overview. A headless
run whose daemon stops sending for DAEMON_GONE_S ends with one line (exit status 2),
its video finished."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from sasprobe.render.lighting.settings import DEFAULT_PROBE_RANGE, LightingSettings
from sasprobe.render.source import RenderSource

from sasprobe.common.errors import UserError

log = logging.getLogger("sasprobe")

OVERVIEW_TILT_DEG = -60.0  # --overview-first: the cube on the molecule, not in front of it
DAEMON_GONE_S = 3.0  # a headless --connect run ends when the daemon has been silent this long


@dataclass
class RenderOptions:
    molecule: str | None = None
    connect: str | None = None  # None: standalone; "" default endpoint
    control: str | None = None
    headless: bool = False
    size: tuple[int, int] = (1280, 720)
    frames: int | None = None
    seconds: float | None = None
    out: Path | None = None
    fps: float = 30.0
    gbuffer: Path | None = None
    camera: dict | None = None
    orbit: float = 0.0
    spheres: str = "quad"
    probe: list[float] | None = None
    touched: int = -1
    probe_radius: float | None = None
    nav_cube: list[float] | None = None
    clip: list[list[float]] = field(default_factory=list)
    probe_plane: bool | None = None  # None: on in the workspace view, off in the overview
    light: list[float] | None = None
    backbone: bool = False
    fxaa: bool = True
    readout: bool = True  # following a daemon headless: its readout over every picture
    # Following a daemon headless in the workspace view: the overview for the first seconds
    overview_first_s: float | None = None
    keep_water: bool = False
    lighting: LightingSettings | None = None  # None: no lighting passes
    lighting_required: bool = False  # asked for explicitly: no OpenGL 4.3 is an error
    probe_light_range: float = DEFAULT_PROBE_RANGE
    snapshot: Path | None = None  # also write the last frame as a PNG (headless)
    report: Path | None = None  # write frame and pose counts as JSON at the end
    # Keep the molecule layer while only the probe moves (render/frame_planner.py)
    frame_cache: bool = True
    # "workspace" or "overview"; None: workspace with --connect, else overview.
    view: str | None = None
    gbuffer_dir: Path | None = None  # headless: every frame's G-buffer into this folder
    color: str | None = None  # colour scheme (molecule/colors.py); None: the default by structure
    # Lighting preset (render/lighting/presets.py): light intensities, background.
    preset: str = "default"
    background: tuple[float, float, float] | None = None  # None: the preset's
    # "camera": lights turn with the view; "molecule": fixed in the molecule frame.
    light_frame: str = "camera"
    # With connect: CURVE client keys from `sasprobe keys DIR` (a keyed daemon)
    keys: Path | None = None

    @property
    def start_view(self) -> str:
        from sasprobe.render.workspace_view import OVERVIEW, WORKSPACE

        if self.view is not None:
            return self.view
        return WORKSPACE if self.connect is not None and self.camera is None else OVERVIEW

    def effects(self):
        """The scene's switches: the options' FXAA, probe plane (on in the workspace view) and
        initial lighting."""
        from sasprobe.render.scene_state import Effects
        from sasprobe.render.workspace_view import WORKSPACE

        lighting = self.lighting.effects() if self.lighting is not None else {}
        probe_plane = self.start_view == WORKSPACE if self.probe_plane is None else self.probe_plane
        return Effects(fxaa=self.fxaa, probe_plane=probe_plane, color_scheme=self.color, **lighting)

    def shading(self):
        """The shading pass's settings: the preset's lights and background (or --background)."""
        from sasprobe.render.lighting.presets import PRESETS
        from sasprobe.render.lighting.settings import ShadingSettings

        shading = PRESETS[self.preset].shading(ShadingSettings(probe_range=self.probe_light_range))
        return (
            shading
            if self.background is None
            else replace(shading, background=tuple(self.background))
        )


def build_scene(structure, opts: RenderOptions, effects=None):
    """The SceneState for a structure: the options' planes, probe, cube and light."""
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS
    from sasprobe.render.scene_state import NavCube, Probe, SceneState

    radius = opts.probe_radius or DEFAULT_PROBE_RADIUS
    if effects is None:
        effects = opts.effects()
    if opts.lighting is not None:
        try:
            opts.lighting.check_soft_shell(radius)
        except ValueError as exc:
            raise UserError(f"--soft-shell: {exc}") from None
    scene = SceneState(
        structure,
        probe_radius=radius,
        clip_planes=[np.array(p) for p in opts.clip],
        effects=effects,
        lights_follow_camera=opts.light_frame == "camera",
    )
    if opts.touched >= structure.n_atoms:
        raise UserError(
            f"--touched {opts.touched}: {structure.name} has atoms 0..{structure.n_atoms - 1}"
        )
    if opts.probe is not None:
        scene.probe = Probe(
            center=np.array(opts.probe, dtype=np.float64), radius=radius, touched_atom=opts.touched
        )
    if opts.nav_cube is not None:
        scene.nav_cube = NavCube(
            center=np.array(opts.nav_cube[:3], dtype=np.float64), half=float(opts.nav_cube[3])
        )
    if opts.light is not None:
        v = np.array(opts.light, dtype=np.float64)
        scene.light_direction = v / np.linalg.norm(v)
    return scene


def initial_camera(scene, opts: RenderOptions):
    """The --camera spec, what it leaves out framed to the molecule's atoms."""
    from sasprobe.render.camera import camera_from_spec

    centers, radii = scene.framing_spheres()
    return camera_from_spec(opts.camera or {}, centers, radii, opts.size[0] / opts.size[1])


def open_source(opts: RenderOptions) -> RenderSource:
    """A StaticSource for --molecule (or the embedded 1CRN), a DaemonSource for --connect."""
    if opts.connect is None:
        from sasprobe.molecule import load_structure_or_default
        from sasprobe.render.source import StaticSource

        return StaticSource(load_structure_or_default(opts.molecule, keep_water=opts.keep_water))
    from sasprobe.render.follow.daemon_source import DaemonSource

    keys = None
    if opts.keys is not None:
        from sasprobe.protocol.security import load_client_keys

        keys = load_client_keys(opts.keys)
    return DaemonSource(opts.connect or None, opts.control, keep_water=opts.keep_water, keys=keys)


def render_main(opts: RenderOptions) -> int:
    from sasprobe.render.gl.context import display_available

    window_mode = not opts.headless and display_available()
    source = open_source(opts)
    try:
        return _run_window(opts, source) if window_mode else _run_headless(opts, source)
    finally:
        source.close()


def make_renderer(ctx, scene, size, opts: RenderOptions, wait_for_areas: bool = True):
    """The renderer of the options, lighting included when asked for and supported;
    `wait_for_areas`: False in a window (the sas colours come once computed)."""
    from sasprobe.render.renderer import Renderer

    renderer = Renderer(
        ctx,
        scene,
        size,
        sphere_mode=opts.spheres,
        backbone_always=opts.backbone,
        shading=opts.shading(),
        wait_for_areas=wait_for_areas,
        frame_cache=opts.frame_cache,
    )
    if opts.lighting is not None:
        try:
            renderer.install_lighting(opts.lighting, required=opts.lighting_required)
        except Exception:
            renderer.release()
            raise
    return renderer


def _writer(opts: RenderOptions, frames: int | None):
    from sasprobe.render.output import FrameWriter

    return FrameWriter(opts.out, frames, opts.fps) if opts.out is not None else None


def _run_headless(opts: RenderOptions, source: RenderSource) -> int:
    from sasprobe.render.gl.context import create_headless_context
    from sasprobe.render.headless import run_headless
    from sasprobe.render.workspace_view import WorkspaceView, overview_camera, tilted_axes

    from sasprobe.common.progress import progress_bar

    source.poll()  # a daemon: its structure is fetched on a thread while the GL context is made
    ctx = create_headless_context()
    try:
        source.wait_ready()  # a daemon: its structure and a first pose, or one clear line
        scene = build_scene(source.take_new_structure(), opts)
        renderer = make_renderer(ctx, scene, opts.size, opts)
    except Exception:
        ctx.release()
        raise
    view = WorkspaceView(opts.start_view)  # headless never turns the view: it follows the daemon's
    camera = initial_camera(scene, opts)
    frames = opts.frames if (opts.frames is not None or opts.seconds is not None) else 1
    writer = _writer(opts, frames)
    bar = progress_bar(frames, "render", unit="frame") if frames and frames > 1 else None
    annotate = None
    if opts.readout and source.follows_daemon:  # where the probe is, as the window says it
        from sasprobe.render.readout_text import draw_text, readout_lines

        source.show_live_clearance()

        def annotate(image):  # the daemon is there (wait_ready): no 'waiting for' status
            return draw_text(image, readout_lines(replace(source.readout(), status="")))

    aspect = opts.size[0] / opts.size[1]
    overview_until = None  # the first frame's time plus --overview-first, once it is known
    overview_s = opts.overview_first_s if view.workspace and source.follows_daemon else None
    workspace_plane = scene.effects.probe_plane

    def update():
        """The newest pose and scene into the renderer's; a new renderer when the daemon
        serves another structure (returned: run_headless draws with it from then on)."""
        nonlocal scene, renderer
        source.poll()
        if source.lost_for_s() > DAEMON_GONE_S:
            raise UserError(
                f"the daemon stopped sending (nothing for {DAEMON_GONE_S:g} s): ending the render"
            )
        structure = source.take_new_structure()  # a daemon that loaded another one
        if structure is not None:
            old = renderer
            scene = build_scene(structure, opts, effects=scene.effects)
            renderer = make_renderer(ctx, scene, opts.size, opts)
            old.release()
            move_camera(initial_camera(scene, opts))
        source.apply(scene)
        follow_camera()
        return renderer if structure is not None else None

    def move_camera(shown) -> None:
        camera.eye, camera.target, camera.up, camera.fov_y = (
            shown.eye,
            shown.target,
            shown.up,
            shown.fov_y,
        )

    def follow_camera() -> None:
        """The overview first (--overview-first), then the workspace view's camera."""
        nonlocal overview_until
        if overview_s is not None:
            overview_until = overview_until or time.monotonic() + overview_s
            overview = time.monotonic() < overview_until
            scene.effects.probe_plane = workspace_plane and not overview
            if overview:  # the whole molecule, seen from above the cube
                axes = tilted_axes(view.axes(source.view_axes()), OVERVIEW_TILT_DEG)
                move_camera(overview_camera(scene, aspect, axes))
                return
        follow = view.camera(scene, aspect, source.view_axes())
        if follow is not None:
            move_camera(follow)

    # A live daemon into a video: keep the video in wall-clock time (see run_headless).
    pace = opts.fps if opts.connect is not None and writer is not None and writer.is_video else None
    try:
        stats = run_headless(
            renderer,
            camera,
            frames,
            opts.seconds,
            writer=writer,
            gbuffer_path=opts.gbuffer,
            orbit_deg=opts.orbit,
            update=update,
            progress=bar,
            pace_fps=pace,
            gbuffer_dir=opts.gbuffer_dir,
            annotate=annotate,
        )
        if opts.snapshot is not None:
            from sasprobe.render.output import FrameWriter

            image = renderer.read_image()
            FrameWriter(opts.snapshot, 1, opts.fps).write(
                image if annotate is None else annotate(image)
            )
    finally:
        if bar is not None:
            bar.close()
        if writer is not None:
            writer.close()
        renderer.release()
        ctx.release()
    dropped = source.readout().dropped
    if dropped:
        log.warning("dropped %d malformed message(s) from the daemon", dropped)
    _report(stats.summary(), writer, opts, "" if opts.headless else " (no display: drawn headless)")
    _write_run_report(opts, stats.as_dict(), source)
    if stats.interrupted == "SIGINT":
        raise KeyboardInterrupt  # outputs are complete; the CLI still ends with 'interrupted'
    return 0


def _run_window(opts: RenderOptions, source: RenderSource) -> int:
    import glfw
    from sasprobe.render.gl.context import create_window
    from sasprobe.render.window.window_app import WindowApp

    window, ctx = create_window(opts.size, "sasprobe render")
    try:

        def build(structure, effects):
            scene = build_scene(structure, opts, effects)
            renderer = make_renderer(
                ctx, scene, glfw.get_framebuffer_size(window), opts, wait_for_areas=False
            )
            glfw.set_window_title(
                window, f"sasprobe render: {structure.name} ({structure.n_atoms} atoms)"
            )
            return renderer, initial_camera(scene, opts)

        # Ctrl+S / Ctrl+R go there
        folder = opts.out if opts.out is not None and opts.out.is_dir() else None
        app = WindowApp(
            window,
            ctx,
            source,
            build,
            "sasprobe render",
            opts.effects(),
            opts.start_view,
            preset=opts.preset,
            background=opts.background,
            shots=folder,
        )
        writer = _writer(opts, 1) if folder is None else None
        log.info("window open: %dx%d framebuffer", *glfw.get_framebuffer_size(window))
        start = time.perf_counter()
        try:
            count = app.run(
                frames=opts.frames, seconds=opts.seconds, writer=writer, gbuffer_path=opts.gbuffer
            )
        finally:
            if writer is not None:
                writer.close()
            app.release()
        seconds = time.perf_counter() - start
        _report(f"{count} frame(s) shown", writer, opts)
        planner = app.renderer.planner if app.renderer is not None else None
        _write_run_report(
            opts,
            {
                "frames": count,
                "seconds": seconds,
                "fps": count / seconds if count else None,
                "window": True,
                "molecule_layer": planner.layer_counts() if planner else None,
            },
            source,
        )
    finally:
        glfw.destroy_window(window)
        glfw.terminate()
    return 0


def _write_run_report(opts: RenderOptions, frames: dict, source: RenderSource) -> None:
    """--report: frame counts, and with a daemon the poses received and lost (seq gaps)."""
    if opts.report is None:
        return
    import json

    report = {"size": list(opts.size), **frames}
    stream = source.stream_report()
    if stream is not None:
        report["daemon"] = stream
    opts.report.write_text(json.dumps(report, indent=1))


def _report(summary: str, writer, opts: RenderOptions, how: str = "") -> None:
    """Where the pictures went, one line each on stdout (`how`: why headless, if not asked)."""
    log.info(summary)
    if writer is not None and writer.written:
        shown = (
            writer.written[0]
            if len(writer.written) == 1
            else f"{writer.written[0]} .. {writer.written[-1]}"
        )
        print(f"wrote {shown}{how}")
    for also in (opts.snapshot, opts.gbuffer):
        if also is not None:
            print(f"wrote {also}")
