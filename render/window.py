"""The interactive window (glfw): arcball rotate, zoom, pan, a key per effect and an
on-screen readout of fps, haptic rate and force."""

from __future__ import annotations

import signal
import time
from collections import deque
from typing import Callable

import numpy as np

from sasprobe.render.camera import Camera
from sasprobe.render.gbuffer_export import gbuffer_arrays, save_gbuffer
from sasprobe.render.lighting.settings import ShadingSettings
from sasprobe.render.passes.lighting import lighting_of, lighting_status
from sasprobe.render.passes.overlay import TextOverlay
from sasprobe.render.scene import Effects
from sasprobe.render.gl.programs import ProgramCache
from sasprobe.render.gl.textures import read_image
from sasprobe.render.source import Readout

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
HELP = [
    "drag: rotate   right/middle drag or shift+drag: pan   wheel: zoom",
    *[f"{k}: {label}" for k, (_, label) in TOGGLES.items()],
    "M: sphere mode (quad/sprite)   C: AO method   R: reset camera   H: help   Q/Esc: quit",
    "Enter: drop a mark at the probe (with a daemon)",
]


def clearance_line(ro: Readout) -> str:
    """Room at the probe (Å): clearance at its centre, passage across its path, narrowest so far."""
    passage = "open" if ro.passage_A is None else f"{ro.passage_A:.2f} Å"
    bottleneck = "-" if ro.bottleneck_A is None else f"{ro.bottleneck_A:.2f} Å"
    return f"clearance {ro.clearance_A:.2f} Å   passage {passage}   bottleneck {bottleneck}"


class WindowApp:
    """The window's loop. `build(structure, effects)` makes a (renderer, camera) for a
    structure; it runs again when the source brings a new one (a daemon that loaded
    another molecule). Until the first structure arrives, the window shows the text."""

    def __init__(self, window, ctx, source, build: Callable, title: str, effects: Effects):
        import glfw

        self.glfw = glfw
        self.window = window
        self.ctx = ctx
        self.source = source
        self.build = build
        self.title = title
        self.effects = effects  # kept across rebuilds: the user's toggles
        self.renderer = None
        self.camera: Camera | None = None
        self.home: Camera | None = None
        self.programs = ProgramCache(ctx)
        self.overlay = TextOverlay(ctx, self.programs)
        self.readout = Readout()
        source.show_live_clearance()
        self.show_help = False
        self.frame_times: deque[float] = deque(maxlen=60)
        self._drag: str | None = None
        self._last_pos = (0.0, 0.0)
        self._stop = False
        glfw.set_key_callback(window, self._on_key)
        glfw.set_mouse_button_callback(window, self._on_button)
        glfw.set_cursor_pos_callback(window, self._on_cursor)
        glfw.set_scroll_callback(window, self._on_scroll)

    # ------------------------------------------------------------ input
    def _on_key(self, window, key, scancode, action, mods) -> None:
        glfw = self.glfw
        if action != glfw.PRESS:
            return
        name = glfw.get_key_name(key, scancode)
        name = name.upper() if name else ""
        fx = self.effects
        if key in (glfw.KEY_ESCAPE,) or name == "Q":
            glfw.set_window_should_close(window, True)
        elif key in (glfw.KEY_ENTER, glfw.KEY_KP_ENTER):
            self.source.drop_mark()
        elif name in TOGGLES:
            field_name = TOGGLES[name][0]
            setattr(fx, field_name, not getattr(fx, field_name))
        elif name == "M" and self.renderer is not None:
            i = SPHERE_MODES.index(self.renderer.sphere_mode) if self.renderer.sphere_mode in SPHERE_MODES else -1
            self.renderer.set_sphere_mode(SPHERE_MODES[(i + 1) % len(SPHERE_MODES)])
        elif name == "C" and self.renderer is not None and lighting_of(self.renderer) is not None:
            lighting_of(self.renderer).cycle_ao_mode()
        elif name == "R" and self.camera is not None:
            self.camera.eye, self.camera.target, self.camera.up = self.home.eye.copy(), self.home.target.copy(), self.home.up.copy()
        elif name == "H" or key == glfw.KEY_F1:
            self.show_help = not self.show_help

    def _on_button(self, window, button, action, mods) -> None:
        glfw = self.glfw
        if action == glfw.PRESS:
            pan = button in (glfw.MOUSE_BUTTON_RIGHT, glfw.MOUSE_BUTTON_MIDDLE) or (mods & glfw.MOD_SHIFT)
            self._drag = "pan" if pan else "rotate"
            self._last_pos = glfw.get_cursor_pos(window)
        elif action == glfw.RELEASE:
            self._drag = None

    def _on_cursor(self, window, x: float, y: float) -> None:
        if self._drag is None or self.camera is None:
            return
        w, h = self.glfw.get_window_size(window)
        x0, y0 = self._last_pos
        self._last_pos = (x, y)
        if self._drag == "rotate":
            ndc = lambda px, py: (2.0 * px / max(w, 1) - 1.0, 1.0 - 2.0 * py / max(h, 1))  # noqa: E731
            self.camera.arcball(ndc(x0, y0), ndc(x, y))
        else:
            self.camera.pan(x - x0, y - y0, h)

    def _on_scroll(self, window, dx: float, dy: float) -> None:
        if self.camera is not None:
            self.camera.zoom(0.9 ** dy)

    def request_stop(self, *_args) -> None:
        self._stop = True

    # ------------------------------------------------------------ loop
    def text(self) -> list[str]:
        r = self.renderer
        fps = len(self.frame_times) / sum(self.frame_times) if self.frame_times and sum(self.frame_times) > 0 else 0.0
        lines = [self.title if r is None else f"{self.title}: {r.scene.structure.name} ({r.scene.structure.n_atoms} atoms)"]
        if r is not None:
            lines.append(f"{fps:5.1f} fps   {r.buffers.n_selected} spheres ({r.sphere_mode})")
            if lighting_of(r) is not None:
                lines.append(lighting_status(r))
        ro = self.readout
        if ro.status:
            lines.append(ro.status)
        if ro.haptic_hz is not None:
            force = f"{ro.force_n:.2f} N" if ro.force_n is not None else "-"
            lines.append(f"haptic {ro.haptic_hz:6.0f} Hz   force {force}")
        if ro.clearance_A is not None:
            lines.append(clearance_line(ro))
        if ro.note:
            lines.append(ro.note)
        if ro.dropped:
            lines.append(f"dropped malformed messages: {ro.dropped}")
        lines += HELP if self.show_help else ["H: help"]
        return lines

    def _take_structure(self) -> None:
        structure = self.source.take_new_structure()
        if structure is None:
            return
        if self.renderer is not None:
            self.renderer.release()
        self.renderer, camera = self.build(structure, self.effects)
        self.camera = camera
        self.home = Camera(camera.eye, camera.target, camera.up, camera.fov_y)

    def _draw(self, size: tuple[int, int], text: list[str] | None) -> None:
        screen = self.ctx.screen
        if self.renderer is not None:
            self.source.apply(self.renderer.scene)
            self.renderer.resize(size)
            self.renderer.render(self.camera, output_fbo=screen)
        else:
            screen.use()
            screen.viewport = (0, 0, *size)
            screen.clear(*ShadingSettings().background, 1.0)
        if self.effects.readout and text is not None:
            self.overlay.draw(screen, size, text)

    def run(self, frames: int | None = None, seconds: float | None = None, writer=None, gbuffer_path=None) -> int:
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
                done = (frames is not None and count + 1 >= frames) or (
                    frames is None and seconds is not None and time.perf_counter() - start >= seconds)
                if writer is not None and (done or writer.is_video):  # PNG: a screenshot of the last frame
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
        if gbuffer_path is not None and self.renderer is not None and self.renderer.last_frame is not None:
            save_gbuffer(gbuffer_path, gbuffer_arrays(self.renderer))
        return count

    def _screenshot(self, size: tuple[int, int]) -> np.ndarray:
        """The window's back buffer, H x W x 3, row 0 = top."""
        return read_image(self.ctx.screen, size)

    def release(self) -> None:
        if self.renderer is not None:
            self.renderer.release()
        self.overlay.release()
        self.programs.release()
