"""Run by tests/test_render_window.py under Xvfb (DISPLAY set): what a real glfw window shows,
read from its screenshot (the back buffer it shows next). H's help is whole: the panel fits
the window and the glyphs of its last line are drawn; Tab's overview frames the molecule,
its cube and trace across the picture; before a daemon's structure arrives the window shows
the cube's wire and the probe under its progress line. Prints 'keys ok'."""

from __future__ import annotations

import numpy as np

from tests.support.window import glfw_window, press

SIZE = (600, 440)  # within the test X screen (640x480)
OVERLAY_AT = 8  # the readout's top-left corner (TextOverlay.draw's default)


def help_line_glyphs(lines: list[str]) -> tuple[np.ndarray, tuple[int, int]]:
    """The last line's band in the readout's image as a mask of its glyphs' bright pixels (full
    size, other rows False, the rest of the band False), its rows, and the image's size."""
    from PIL import Image, ImageDraw
    from sasprobe.render.text import PADDING, fit_text, text_font, text_image

    image = text_image(lines)
    font = text_font()[0]
    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    line_h = (
        max(
            probe.textbbox((0, 0), fit_text(line) or " ", font=font)[3]
            - probe.textbbox((0, 0), fit_text(line) or " ", font=font)[1]
            for line in lines
        )
        + 3
    )
    top = PADDING + (len(lines) - 1) * line_h
    return image[..., :3].min(axis=2) >= 200, slice(top, top + line_h), image.shape[:2]


def molecule_extent(shot: np.ndarray, background) -> tuple[float, float]:
    """The fraction of the picture's width and height that pixels other than the background span."""
    drawn = np.abs(shot.astype(int) - np.asarray(background)).max(axis=2) > 30
    rows, cols = np.nonzero(drawn)
    return (cols.max() - cols.min() + 1) / shot.shape[1], (
        rows.max() - rows.min() + 1
    ) / shot.shape[0]


def main() -> None:
    import glfw
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS, load_default
    from sasprobe.render.app import RenderOptions, build_scene, initial_camera, make_renderer
    from sasprobe.render.passes.navcube import WIRE_COLOR
    from sasprobe.render.passes.probe import PROBE_COLOR
    from sasprobe.render.scene_state import NavCube, Probe
    from sasprobe.render.source import Readout, RenderSource, StaticSource
    from sasprobe.render.window.window_app import HELP, WindowApp
    from sasprobe.render.workspace_view import OVERVIEW

    structure = load_default()
    top = int(np.argmax(structure.positions[:, 2]))
    probe = structure.positions[top] + np.array(
        [0.0, 0.0, structure.vdw_radii[top] + DEFAULT_PROBE_RADIUS]
    )
    centre = structure.positions.mean(axis=0)
    # the daemon's default cube on 1CRN: a fifth of its smallest width, about the probe
    opts = RenderOptions(size=SIZE, probe=probe.tolist(), nav_cube=[*probe, 5.57], view="workspace")
    with glfw_window(SIZE, "layout") as (window, ctx):
        size = glfw.get_framebuffer_size(window)

        def build(structure, effects):
            scene = build_scene(structure, opts, effects)
            return make_renderer(ctx, scene, size, opts), initial_camera(scene, opts)

        app = WindowApp(
            window, ctx, StaticSource(structure), build, "test", opts.effects(), opts.start_view
        )

        def frame() -> np.ndarray:
            app.run(frames=1)
            return app._screenshot(size)

        # H: the whole help, within the window
        frame()
        press(app, glfw.KEY_H)
        shot = frame()
        lines = app.text()
        assert lines[-len(HELP) :] == HELP
        glyphs, band, (height, width) = help_line_glyphs(lines)
        assert height + OVERLAY_AT <= size[1] and width + OVERLAY_AT <= size[0], (
            (width, height),
            size,
        )
        glyphs = glyphs[band]
        shown = (
            shot[OVERLAY_AT : OVERLAY_AT + height, OVERLAY_AT : OVERLAY_AT + width][band].min(
                axis=2
            )
            >= 160
        )
        assert glyphs.sum() > 100, "the help's last line has glyphs"
        assert shown[glyphs].mean() > 0.9 and shown[~glyphs].mean() < 0.1, (
            "the help's last line is not on the screen"
        )
        press(app, glfw.KEY_H)

        # Tab: the overview frames the molecule, its cube and the trace across the picture
        press(app, glfw.KEY_O)  # no readout over the picture
        press(app, glfw.KEY_TAB)
        assert app.view.mode == OVERVIEW
        background = np.round(
            np.array(app.renderer.pass_named("shading").settings.background) * 255
        )
        across, up = molecule_extent(frame(), background)
        assert max(across, up) >= 0.6, (
            f"the overview spans {across:.2f} of the width, {up:.2f} of the height"
        )
        app.release()

        # No structure yet: the cube and the probe where the poses put them, and the progress line
        class Waiting(RenderSource):
            def take_new_structure(self):
                return None

            def preview(self):
                return NavCube(center=centre, half=8.0), Probe(center=centre + [0.0, 0.0, 3.0])

            def readout(self):
                return Readout(status="fetching the structure from tcp://daemon")

        app = WindowApp(window, ctx, Waiting(), build, "test", opts.effects(), opts.start_view)
        shot = frame()
        assert any("fetching the structure" in line for line in app.text())
        below = shot[SIZE[1] // 3 :]  # under the readout

        def near(colour):
            """Pixels under the readout within 12 levels of `colour` in every channel."""
            return (
                np.abs(below.astype(int) - np.round(np.array(colour[:3]) * 255)).max(axis=2) <= 12
            )

        assert near(WIRE_COLOR).sum() > 300, "the cube's wire is drawn"
        assert near(PROBE_COLOR).sum() > 300, "the probe is drawn"
        app.release()
    print("keys ok")


if __name__ == "__main__":
    main()
