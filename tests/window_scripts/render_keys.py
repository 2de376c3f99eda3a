"""Run by tests/test_render_window.py under Xvfb (DISPLAY set): a real glfw window on
1CRN with a probe, a touched atom, a navigation cube and a clipping plane. Every
render key and the mouse go through the window's own handlers; each toggle must flip
its switch and change the picture, and pressing it again must restore the picture
exactly. Prints 'keys ok'."""

from __future__ import annotations

import numpy as np

from tests.support.window import glfw_window, press

SIZE = (240, 180)


def changed_pixels(a: np.ndarray, b: np.ndarray) -> int:
    """Pixels where some channel differs by more than 16 levels."""
    return int((np.abs(a.astype(int) - b.astype(int)).max(axis=2) > 16).sum())


def main() -> None:
    import glfw
    from sasprobe.molecule import DEFAULT_PROBE_RADIUS, load_default
    from sasprobe.render.app import RenderOptions, build_scene, make_renderer
    from sasprobe.render.camera import Camera
    from sasprobe.render.source import StaticSource
    from sasprobe.render.window.window_app import TOGGLES, WindowApp

    structure = load_default()
    # The probe rests on the topmost atom's expanded sphere with the cube centred on it;
    # an oblique plane 3 Å below it caps the atoms it crosses; the camera looks from
    # the side so the probe plane (facing the camera) has atoms in front of it to cut.
    top = int(np.argmax(structure.positions[:, 2]))
    reach = structure.vdw_radii[top] + DEFAULT_PROBE_RADIUS
    probe = structure.positions[top] + np.array([0.0, 0.0, reach])
    normal = np.array([0.3, 0.4, 0.87]) / np.linalg.norm([0.3, 0.4, 0.87])
    opts = RenderOptions(
        size=SIZE,
        probe=probe.tolist(),
        touched=top,
        nav_cube=[*probe, 10.0],
        clip=[[*-normal, float(normal @ (probe - [0.0, 0.0, 3.0]))]],
    )
    with glfw_window(SIZE, "render keys") as (window, ctx):

        def build(structure, effects):
            scene = build_scene(structure, opts, effects)
            center, radius = scene.bounding_sphere()
            camera = Camera.fitted(
                center, radius, SIZE[0] / SIZE[1], direction=(1.0, 0.2, 0.3), up=(0.0, 0.0, 1.0)
            )
            return make_renderer(ctx, scene, glfw.get_framebuffer_size(window), opts), camera

        app = WindowApp(window, ctx, StaticSource(structure), build, "test", opts.effects())
        size = glfw.get_framebuffer_size(window)

        def frame() -> np.ndarray:
            app.run(frames=1)
            return app._screenshot(size)

        with_readout = frame()
        press(app, glfw.KEY_O)  # the readout shows the fps, which changes: off for the rest
        assert not app.effects.readout
        base = frame()
        assert changed_pixels(with_readout, base) > 0, "the readout drew nothing"

        render_keys = {
            k: v
            for k, v in TOGGLES.items()
            if v[0]
            not in (
                "readout",
                "shadows",
                "soft_shadows",
                "ambient_occlusion",
                "edge_cueing",
                "path_tracing",
            )
        }
        assert set(render_keys) == set("FBNWPLDTKX"), render_keys
        for letter, (field, _label) in render_keys.items():
            key = getattr(glfw, f"KEY_{letter}")
            before = getattr(app.effects, field)
            press(app, key)
            assert getattr(app.effects, field) != before, f"{letter} did not switch {field}"
            toggled = frame()
            assert changed_pixels(base, toggled) >= 10, (
                f"{letter} ({field}) changed {changed_pixels(base, toggled)} pixels"
            )
            press(app, key)
            assert getattr(app.effects, field) == before
            again = frame()
            assert changed_pixels(base, again) == 0, (
                f"{letter} ({field}) did not restore the picture"
            )

        press(app, glfw.KEY_M)
        assert app.renderer.sphere_mode == "sprite", app.renderer.sphere_mode
        sprites = frame()
        assert changed_pixels(base, sprites) < 0.05 * base.shape[0] * base.shape[1], (
            "sprites draw other spheres"
        )
        press(app, glfw.KEY_M)
        assert app.renderer.sphere_mode == "quad"

        press(app, glfw.KEY_H)
        assert app.show_help and any("M: sphere mode" in line for line in app.text())
        press(app, glfw.KEY_H)
        assert not app.show_help

        # Drag to turn (left button), then R puts the camera back where it started.
        app._on_button(window, glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
        app._last_pos = (SIZE[0] * 0.5, SIZE[1] * 0.5)
        app._on_cursor(window, SIZE[0] * 0.8, SIZE[1] * 0.4)
        app._on_button(window, glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)
        turned = frame()
        assert changed_pixels(base, turned) > 100, "dragging did not turn the molecule"
        app._on_scroll(window, 0.0, 2.0)
        zoomed = frame()
        assert changed_pixels(turned, zoomed) > 100, "the wheel did not zoom"
        press(app, glfw.KEY_R)
        assert changed_pixels(base, frame()) == 0, "R did not reset the camera"

        press(app, glfw.KEY_Q)
        assert glfw.window_should_close(window)
        app.release()
    print("keys ok")


if __name__ == "__main__":
    main()
