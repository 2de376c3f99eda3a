"""The interactive window (glfw): arcball rotate, zoom to the cursor, pan, a key per effect,
colour schemes and lighting presets, clicking an atom to name it, screenshots and videos,
and an on-screen readout of fps, haptic rate, force against the device's ratings and the
touched residue. Following a daemon it starts in the workspace view (a drag turns the
view, and with it the hand's frame); Tab switches to the whole-molecule overview and
back, Home recentres the cube on the probe, Space held is the clutch."""

from __future__ import annotations

import logging
import signal
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path

import numpy as np
from sasprobe.molecule.sas import atom_areas
from sasprobe.protocol.scene import COLOR_SCHEMES as SCHEMES
from sasprobe.render.camera import Camera
from sasprobe.render.gbuffer_export import gbuffer_arrays, save_gbuffer
from sasprobe.render.gl.programs import ProgramCache
from sasprobe.render.gl.targets import KIND_BACKGROUND, KIND_PROBE
from sasprobe.render.gl.textures import read_image
from sasprobe.render.lighting.presets import PRESET_NAMES, PRESETS
from sasprobe.render.readout_text import readout_lines
from sasprobe.render.scene_state import Effects
from sasprobe.render.source import Readout
from sasprobe.render.window.capture import WindowCapture, atom_label
from sasprobe.render.window.lighting_controls import apply_preset, lighting_status
from sasprobe.render.window.overlay import TextOverlay
from sasprobe.render.window.picking import label_position, pixel_under, point_under
from sasprobe.render.window.waiting_view import WaitingView
from sasprobe.render.workspace_view import OVERVIEW, WORKSPACE, WorkspaceView, overview_camera

log = logging.getLogger("sasprobe")

# key -> (Effects field, label); sphere mode and camera keys are handled separately
TOGGLES = {
    "F": ("fxaa", "FXAA"),
    "B": ("backbone", "backbone trace"),
    "N": ("nav_cube", "navigation-cube culling"),
    "W": ("cube_wire", "navigation-cube wire"),
    "P": ("probe", "probe sphere"),
    "L": ("probe_light", "probe light"),
    "D": ("directional_light", "directional light"),
    "T": ("highlight", "touched-atom highlight"),
    "K": ("clip_planes", "clipping planes"),
    "X": ("probe_plane", "clip plane at the probe"),
    "O": ("readout", "readout"),
    "S": ("shadows", "shadows"),
    "V": ("soft_shadows", "soft shadows"),
    "A": ("ambient_occlusion", "ambient occlusion"),
    "E": ("edge_cueing", "edge cueing"),
    "G": ("path_tracing", "path tracing"),
}
SPHERE_MODES = ("quad", "sprite")
CLUTCH_RENEW_S = 0.3  # the clutch key's lease is renewed this often while Space is down
TOGGLES_PER_LINE = 3
_TOGGLE_TEXTS = [f"{k}: {label}" for k, (_, label) in TOGGLES.items()]
# Short lines, the switches three to a line, so the readout and the help fit a 640x480 window.
HELP = [
    "drag: rotate (workspace view: turns the hand's frame too)",
    "right/middle drag or shift+drag: pan   wheel: zoom   click: name an atom",
    "Tab: workspace view / overview   Home: recentre the cube on the probe",
    "Space (held): clutch   Enter: drop a mark at the probe (with a daemon)",
    *[
        "   ".join(_TOGGLE_TEXTS[i : i + TOGGLES_PER_LINE])
        for i in range(0, len(_TOGGLE_TEXTS), TOGGLES_PER_LINE)
    ],
    "C: colour scheme   I: lighting preset   Shift+A: AO method   Z: centre on the probe",
    "Ctrl+S: screenshot   Ctrl+R: start/stop a video   M: sphere mode (quad/sprite)",
    "R: reset camera   H: help   Q/Esc: quit",
]
CLICK_PIXELS = 3.0  # a press and release closer than this is a click (a pick), not a drag


class WindowApp:
    """The window's loop. `build(structure, effects)` makes a (renderer, camera) for a
    structure; it runs again when the source brings a new one (a daemon that loaded
    another molecule). Until the first structure arrives, the window shows the text.
    `preset`, `background`: the lighting the renderer starts with (I cycles the presets);
    `shots`: where Ctrl+S and Ctrl+R write."""

    def __init__(
        self,
        window,
        ctx,
        source,
        build: Callable,
        title: str,
        effects: Effects,
        view: str = OVERVIEW,
        preset: str = "default",
        background=None,
        shots: Path | None = None,
    ):
        import glfw

        self.glfw = glfw
        self.window = window
        self.ctx = ctx
        self.source = source
        self.build = build
        self.title = title
        self.effects = effects  # kept across rebuilds: the user's toggles and colour scheme
        self.preset = preset
        self.background = background
        self.renderer = None
        self.camera: Camera | None = None
        self.home: Camera | None = None
        self.programs = ProgramCache(ctx)
        self.overlay = TextOverlay(ctx, self.programs)
        self.label_overlay = TextOverlay(ctx, self.programs)
        self.waiting = WaitingView(ctx, self.programs)
        self.readout = Readout()
        source.show_live_clearance()
        self.show_help = False
        self.frame_times: deque[float] = deque(maxlen=60)
        self.picked: tuple[int, str] | None = None  # (atom, label)
        self.capture = WindowCapture(Path.cwd() if shots is None else Path(shots))
        self._drag: str | None = None
        self._press_pos = (0.0, 0.0)
        self._last_pos = (0.0, 0.0)
        self._stop = False
        self.view = WorkspaceView(
            view, send_view=self._send_view if source.follows_daemon else None
        )
        # When the clutch key's lease was last renewed (None: up)
        self._clutch_renewed: float | None = None
        glfw.set_key_callback(window, self._on_key)
        glfw.set_mouse_button_callback(window, self._on_button)
        glfw.set_cursor_pos_callback(window, self._on_cursor)
        glfw.set_scroll_callback(window, self._on_scroll)

    # ------------------------------------------------------------ input
    def _send_view(self, axes) -> None:
        self.source.request("view", rotation=np.asarray(axes, dtype=float).tolist())

    def _clutch_key(self, held: bool) -> None:
        self._clutch_renewed = time.perf_counter() if held else None
        self.source.request("clutch", held=held)

    def _on_key(self, window, key, scancode, action, mods) -> None:
        glfw = self.glfw
        if key == glfw.KEY_SPACE and action in (glfw.PRESS, glfw.RELEASE):
            self._clutch_key(action == glfw.PRESS)
            return
        if action != glfw.PRESS:
            return
        name = glfw.get_key_name(key, scancode)
        name = name.upper() if name else ""
        fx = self.effects
        ctrl, shift = bool(mods & glfw.MOD_CONTROL), bool(mods & glfw.MOD_SHIFT)
        if key in (glfw.KEY_ESCAPE,) or name == "Q":
            glfw.set_window_should_close(window, True)
        elif ctrl and name == "S":
            self.capture.screenshot_due = True
        elif ctrl and name == "R":
            self.capture.toggle_recording()
        elif shift and name == "A":
            if self.renderer is not None and self.renderer.lighting is not None:
                self.renderer.lighting.cycle_ao_mode()
        elif key in (glfw.KEY_ENTER, glfw.KEY_KP_ENTER):
            self.source.drop_mark()
        elif name in TOGGLES:
            field_name = TOGGLES[name][0]
            setattr(fx, field_name, not getattr(fx, field_name))
        elif name == "M" and self.renderer is not None:
            i = (
                SPHERE_MODES.index(self.renderer.sphere_mode)
                if self.renderer.sphere_mode in SPHERE_MODES
                else -1
            )
            self.renderer.set_sphere_mode(SPHERE_MODES[(i + 1) % len(SPHERE_MODES)])
        elif name == "C" and self.renderer is not None:
            current = self.renderer.scene.color_scheme()
            fx.color_scheme = SCHEMES[(SCHEMES.index(current) + 1) % len(SCHEMES)]
        elif name == "I" and self.renderer is not None:
            self.preset = PRESET_NAMES[(PRESET_NAMES.index(self.preset) + 1) % len(PRESET_NAMES)]
            apply_preset(self.renderer, PRESETS[self.preset], self.background)
        elif name == "Z" and self.camera is not None and self.renderer is not None:
            probe = self.renderer.scene.probe
            if probe is not None:
                self.camera.centre_on(probe.center)
        elif key == glfw.KEY_TAB:
            self._toggle_view()
        elif key == glfw.KEY_HOME:
            self.source.request("recentre")
        elif name == "R" and self.camera is not None:
            self.camera.eye, self.camera.target, self.camera.up = (
                self.home.eye.copy(),
                self.home.target.copy(),
                self.home.up.copy(),
            )
            self.view.reset()
        elif name == "H" or key == glfw.KEY_F1:
            self.show_help = not self.show_help

    def _on_button(self, window, button, action, mods) -> None:
        glfw = self.glfw
        if action == glfw.PRESS:
            pan = button in (glfw.MOUSE_BUTTON_RIGHT, glfw.MOUSE_BUTTON_MIDDLE) or (
                mods & glfw.MOD_SHIFT
            )
            self._drag = "pan" if pan else "rotate"
            self._press_pos = self._last_pos = glfw.get_cursor_pos(window)
        elif action == glfw.RELEASE:
            x, y = glfw.get_cursor_pos(window)
            if (
                self._drag == "rotate"
                and np.hypot(x - self._press_pos[0], y - self._press_pos[1]) < CLICK_PIXELS
            ):
                self.pick(x, y)
            elif self._drag == "rotate" and self._workspace_camera() is not None:
                self.view.end_turn()
            self._drag = None

    def _on_cursor(self, window, x: float, y: float) -> None:
        if self._drag is None or self.camera is None:
            return
        w, h = self.glfw.get_window_size(window)
        x0, y0 = self._last_pos
        self._last_pos = (x, y)

        def ndc(px, py):
            return 2.0 * px / max(w, 1) - 1.0, 1.0 - 2.0 * py / max(h, 1)

        workspace = self._workspace_camera() is not None
        if self._drag == "rotate" and workspace:
            self.view.turn(self.source.view_axes(), ndc(x0, y0), ndc(x, y))
        elif self._drag == "rotate":
            self.camera.arcball(ndc(x0, y0), ndc(x, y))
        elif not workspace:  # the workspace view follows the cube: no pan there
            self.camera.pan(x - x0, y - y0, h)

    def _on_scroll(self, window, dx: float, dy: float) -> None:
        if self._workspace_camera() is not None:  # the workspace view stays on the cube
            self.view.zoom_by(0.9**dy)
        elif self.camera is not None:
            point = self.point_under(*self.glfw.get_cursor_pos(window))
            self.camera.zoom_towards(point, 0.9**dy)

    def _aspect(self) -> float:
        w, h = self.glfw.get_framebuffer_size(self.window)
        return w / h if w and h else 16 / 9

    def _workspace_camera(self) -> Camera | None:
        """This frame's workspace camera; None in the overview (or with no cube to frame)."""
        if self.renderer is None:
            return None
        return self.view.camera(self.renderer.scene, self._aspect(), self.source.view_axes())

    def _toggle_view(self) -> None:
        mode = self.view.toggle()
        if self.renderer is None:
            return
        self.effects.probe_plane = mode == WORKSPACE
        if mode == OVERVIEW:  # the whole molecule, from where the workspace view looked
            axes = self.view.axes(self.source.view_axes())
            self.camera = overview_camera(self.renderer.scene, self._aspect(), axes)
            self.home = Camera(
                self.camera.eye, self.camera.target, self.camera.up, self.camera.fov_y
            )

    def request_stop(self, *_args) -> None:
        self._stop = True

    # ------------------------------------------------------------ picking
    def point_under(self, x: float, y: float) -> np.ndarray:
        return point_under(self.renderer, self.camera, self.glfw.get_window_size(self.window), x, y)

    def pick(self, x: float, y: float) -> int | None:
        """Name the atom under the cursor (the G-buffer's atom id there); clicking the
        background or the probe clears the label. Returns the atom or None."""
        hit = pixel_under(self.renderer, self.glfw.get_window_size(self.window), x, y)
        if hit is None or hit[0] < 0 or hit[1] in (KIND_BACKGROUND, KIND_PROBE):
            self.picked = None
            return None
        atom, scene = hit[0], self.renderer.scene
        area = float(atom_areas(scene.grid, [atom])[0])
        self.picked = (atom, atom_label(scene.structure, atom, area))
        log.info("picked atom %d: %s", atom, self.picked[1])
        return atom

    # ------------------------------------------------------------ loop
    def text(self) -> list[str]:
        r = self.renderer
        fps = (
            len(self.frame_times) / sum(self.frame_times)
            if self.frame_times and sum(self.frame_times) > 0
            else 0.0
        )
        lines = [
            self.title
            if r is None
            else f"{self.title}: {r.scene.structure.name} ({r.scene.structure.n_atoms} atoms)"
        ]
        if r is not None:
            lines.append(f"{fps:5.1f} fps   {r.buffers.n_selected} spheres ({r.sphere_mode})")
            scheme = r.scene.color_scheme()
            lines.append(
                f"colour: {scheme}"
                + (" (computing SAS areas...)" if r.colors_pending else "")
                + f"   lighting preset: {self.preset}"
            )
            if r.lighting is not None:
                lines.append(lighting_status(r))
        ro = self.readout
        lines += readout_lines(ro)
        if r is not None and self.source.view_axes() is not None:
            lines.append(
                "workspace view (Tab: overview)"
                if self.view.workspace
                else "overview (Tab: workspace view)"
            )
        if ro.dropped:
            lines.append(f"dropped malformed messages: {ro.dropped}")
        if self.capture.message:
            lines.append(self.capture.message)
        lines += HELP if self.show_help else ["H: help"]
        return lines

    def _take_structure(self) -> None:
        structure = self.source.take_new_structure()
        if structure is None:
            return
        if self.renderer is not None:
            self.renderer.release()
        self.renderer, camera = self.build(structure, self.effects)
        apply_preset(self.renderer, PRESETS[self.preset], self.background)
        self.picked = None
        self.camera = camera
        self.home = Camera(camera.eye, camera.target, camera.up, camera.fov_y)

    def _draw(self, size: tuple[int, int], text: list[str] | None) -> None:
        screen = self.ctx.screen
        if self.renderer is not None:
            self.source.apply(self.renderer.scene)
            self.renderer.resize(size)
            self.renderer.render(self._workspace_camera() or self.camera, output_fbo=screen)
        else:  # no structure yet: the cube and the probe where the poses put them, if they came
            background = self.background or PRESETS[self.preset].background
            cube, probe = self.source.preview()
            if cube is not None:
                self.waiting.draw(screen, size, cube, probe, background)
            else:
                screen.use()
                screen.viewport = (0, 0, *size)
                screen.clear(*background, 1.0)
        if self.effects.readout and text is not None:
            self.overlay.draw(screen, size, text)
        if self.picked is not None and self.renderer is not None:
            self.label_overlay.prepare([self.picked[1]])
            centre = self.renderer.scene.structure.positions[self.picked[0]]
            at = label_position(
                self.renderer.last_frame.viewproj, centre, size, self.label_overlay.size
            )
            if at is not None:
                self.label_overlay.draw(screen, size, [self.picked[1]], at=at)

    def run(
        self,
        frames: int | None = None,
        seconds: float | None = None,
        writer=None,
        gbuffer_path=None,
    ) -> int:
        """Show frames until the window closes, Ctrl-C/SIGTERM, or `frames`/`seconds` are done."""
        glfw = self.glfw
        old_term = signal.signal(signal.SIGTERM, self.request_stop)
        count = 0
        start = time.perf_counter()
        last_text = -1.0
        text: list[str] | None = None
        size = (0, 0)
        try:
            while not glfw.window_should_close(self.window) and not self._stop:
                t0 = time.perf_counter()
                glfw.poll_events()
                if self._clutch_renewed is not None and t0 - self._clutch_renewed > CLUTCH_RENEW_S:
                    self._clutch_key(True)  # Space still down: keep the lease
                self.source.poll()
                self._take_structure()
                self.readout = self.source.readout()
                size = glfw.get_framebuffer_size(self.window)
                if size[0] == 0 or size[1] == 0:  # minimised
                    time.sleep(0.05)
                    continue
                if t0 - last_text > 0.25:
                    text, last_text = self.text(), t0
                self._draw(size, text)
                # What was just drawn: the back buffer, before it is shown
                if self.capture.wants_frame:
                    self.capture.take(self._screenshot(size))
                done = (frames is not None and count + 1 >= frames) or (
                    frames is None
                    and seconds is not None
                    and time.perf_counter() - start >= seconds
                )
                # PNG: a screenshot of the last frame
                if writer is not None and (done or writer.is_video):
                    writer.write(self._screenshot(size))
                glfw.swap_buffers(self.window)
                self.frame_times.append(time.perf_counter() - t0)
                count += 1
                if done:
                    break
            if writer is not None and writer.count == 0 and size[0] and size[1]:
                # Closed early (window, Ctrl-C, SIGTERM): the screenshot is of one more frame.
                self._draw(size, text)
                writer.write(self._screenshot(size))
        finally:
            signal.signal(signal.SIGTERM, old_term)
        if (
            gbuffer_path is not None
            and self.renderer is not None
            and self.renderer.last_frame is not None
        ):
            save_gbuffer(gbuffer_path, gbuffer_arrays(self.renderer))
        return count

    def _screenshot(self, size: tuple[int, int]) -> np.ndarray:
        """The window's back buffer, H x W x 3, row 0 = top."""
        return read_image(self.ctx.screen, size)

    def release(self) -> None:
        if self._clutch_renewed is not None:
            self._clutch_key(False)  # never leave the daemon clutched
        self.capture.close()
        if self.renderer is not None:
            self.renderer.release()
        self.overlay.release()
        self.label_overlay.release()
        self.waiting.release()
        self.programs.release()
