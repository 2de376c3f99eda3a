"""Run by tests/test_render_window.py under Xvfb (DISPLAY set): a real glfw window on 1CRN
with a probe beside it. Checks, through the window's own handlers:
- a click names the atom under the cursor: the one a numpy ray cast finds at that pixel
  (nearest sphere hit), with its chain, residue, atom name, element and the SAS area
  `shrake_rupley` gives it; the label appears in the picture; a click on the background
  clears it;
- Ctrl+S writes a timestamped PNG equal to what the X server shows of the window
  (XGetImage, independent of GL);
- Ctrl+R starts and stops an MP4 of the window's size;
- the wheel zooms about the point under the cursor (it stays at its pixel);
- C cycles the colour schemes, I the lighting presets, each changing the picture;
- Z centres the view on the probe.
Prints 'keys ok'."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from tests.support.window import glfw_window, press, x_window_image

SIZE = (240, 180)


def ray_cast_atom(structure, camera, aspect: float, px: float, py: float) -> int:
    """The atom whose van der Waals sphere the pixel's ray meets first (brute force)."""
    t = np.tan(np.radians(camera.fov_y) / 2.0)
    ndc = (2.0 * px / SIZE[0] - 1.0, 1.0 - 2.0 * py / SIZE[1])
    forward = camera.target - camera.eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, camera.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = forward + ndc[0] * t * aspect * right + ndc[1] * t * up
    d /= np.linalg.norm(d)
    oc = structure.positions - camera.eye
    b = oc @ d
    h = structure.vdw_radii**2 - (np.einsum("ij,ij->i", oc, oc) - b * b)
    hit = h >= 0
    t_hit = np.where(hit, b - np.sqrt(np.where(hit, h, 0.0)), np.inf)
    return int(np.argmin(t_hit)) if np.isfinite(t_hit.min()) else -1


def project(camera, aspect: float, point) -> np.ndarray:
    clip = camera.projection(aspect) @ camera.view() @ np.array([*point, 1.0])
    ndc = clip[:2] / clip[3]
    return np.array([(ndc[0] + 1.0) / 2.0 * SIZE[0], (1.0 - ndc[1]) / 2.0 * SIZE[1]])


def click(app, window, x: float, y: float) -> None:
    import glfw

    glfw.set_cursor_pos(window, x, y)
    app._on_button(window, glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
    app._on_button(window, glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)


def changed(a: np.ndarray, b: np.ndarray) -> int:
    return int((np.abs(a.astype(int) - b.astype(int)).max(axis=2) > 16).sum())


def main() -> int:
    import glfw
    import imageio.v2 as iio2
    import imageio.v3 as iio
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid, load_default
    from sasprobe.molecule.sas import shrake_rupley
    from sasprobe.render.app import RenderOptions, build_scene, initial_camera, make_renderer
    from sasprobe.render.lighting.presets import PRESET_NAMES
    from sasprobe.render.source import StaticSource
    from sasprobe.render.window.window_app import WindowApp

    structure = load_default()
    areas = shrake_rupley(
        UniformGrid(structure.positions, structure.expanded_radii(DEFAULT_PROBE_RADIUS))
    ).areas
    side = int(np.argmax(structure.positions[:, 0]))
    probe = structure.positions[side] + [structure.vdw_radii[side] + DEFAULT_PROBE_RADIUS, 0.0, 0.0]
    opts = RenderOptions(size=SIZE, probe=probe.tolist())
    aspect = SIZE[0] / SIZE[1]
    shots = Path(tempfile.mkdtemp(prefix="sasprobe-shots-"))
    with glfw_window(SIZE, "pick check") as (window, ctx):
        assert glfw.get_framebuffer_size(window) == SIZE, (
            "the checks assume window pixels = framebuffer pixels"
        )

        def build(structure, effects):
            scene = build_scene(structure, opts, effects)
            return make_renderer(ctx, scene, SIZE, opts, wait_for_areas=False), initial_camera(
                scene, opts
            )

        app = WindowApp(
            window, ctx, StaticSource(structure), build, "pick", opts.effects(), shots=shots
        )
        app.run(frames=1)
        press(app, glfw.KEY_O)  # no readout: the label is the only text
        app.run(frames=1)
        before = app._screenshot(SIZE)

        # --- a click names the atom under the cursor
        cam = app.camera
        front = int(np.argmin(np.linalg.norm(structure.positions - cam.eye, axis=1)))
        x, y = project(cam, aspect, structure.positions[front])
        expected = ray_cast_atom(structure, cam, aspect, x + 0.5, y + 0.5)
        assert expected >= 0
        click(app, window, x, y)
        assert app.picked is not None and app.picked[0] == expected, (app.picked, expected)
        label = app.picked[1]
        s = structure
        for part in (
            f"chain {s.chain_ids[expected]}",
            f"{s.residue_names[expected]} {s.residue_numbers[expected]}",
            f"{s.atom_names[expected]} ({s.elements[expected]})",
            f"SAS {areas[expected]:.1f}",
        ):
            assert part in label, (part, label)
        app.run(frames=1)
        labelled = app._screenshot(SIZE)
        assert changed(before, labelled) > 200, "the label is not drawn"
        click(app, window, 2.0, 2.0)  # the background (the corner)
        assert app.picked is None
        app.run(frames=1)
        assert changed(before, app._screenshot(SIZE)) == 0, (
            "clearing the label did not restore the picture"
        )
        click(app, window, x, y)

        # --- Ctrl+S: a PNG equal to what the X server shows
        shadows = app.effects.shadows
        press(app, glfw.KEY_S, glfw.MOD_CONTROL)
        app.run(frames=1)
        assert app.effects.shadows == shadows, "Ctrl+S switched the shadows (the S key)"
        pngs = sorted(shots.glob("sasprobe-*.png"))
        assert len(pngs) == 1, pngs
        on_screen = x_window_image(window)
        written = iio.imread(pngs[0])[..., :3]
        assert written.shape == on_screen.shape == (SIZE[1], SIZE[0], 3), (
            written.shape,
            on_screen.shape,
        )
        diff = np.abs(written.astype(int) - on_screen.astype(int)).max()
        assert diff <= 1, f"the screenshot differs from the window by up to {diff} levels"
        assert changed(before, written) > 200, "the screenshot lacks the label"

        # --- Ctrl+R: a video of the window
        press(app, glfw.KEY_R, glfw.MOD_CONTROL)
        app.run(frames=3)
        press(app, glfw.KEY_R, glfw.MOD_CONTROL)
        videos = sorted(shots.glob("sasprobe-*.mp4"))
        assert len(videos) == 1 and videos[0] in app.capture.saved, videos
        reader = iio2.get_reader(str(videos[0]))
        first = reader.get_data(0)
        reader.close()
        assert first.shape == (SIZE[1], SIZE[0], 3), first.shape

        # --- the wheel zooms about the point under the cursor
        px, py = SIZE[0] * 0.3, SIZE[1] * 0.6
        glfw.set_cursor_pos(window, px, py)
        anchor = app.point_under(px, py)
        distance = app.camera.distance
        app._on_scroll(window, 0.0, 2.0)
        assert app.camera.distance < distance
        np.testing.assert_allclose(project(app.camera, aspect, anchor), [px, py], atol=0.75)

        # --- C: the next colour scheme; I: the next preset
        app.run(frames=1)
        base = app._screenshot(SIZE)
        scheme = app.renderer.scene.color_scheme()
        press(app, glfw.KEY_C)
        assert app.renderer.scene.color_scheme() != scheme
        app.run(frames=1)
        assert changed(base, app._screenshot(SIZE)) > 200, "C did not recolour"
        preset = app.preset
        press(app, glfw.KEY_I)
        assert app.preset == PRESET_NAMES[(PRESET_NAMES.index(preset) + 1) % len(PRESET_NAMES)]
        app.run(frames=1)
        assert changed(base, app._screenshot(SIZE)) > 200, "I did not change the lighting"

        # --- Z: the probe in the middle of the view
        press(app, glfw.KEY_Z)
        np.testing.assert_allclose(
            project(app.camera, aspect, probe), [SIZE[0] / 2, SIZE[1] / 2], atol=1e-6
        )
        app.release()
    print("keys ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
