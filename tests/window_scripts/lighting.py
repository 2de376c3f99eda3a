"""Run by tests/test_render_lighting_render.py under Xvfb (DISPLAY set): a real glfw window with
the lighting, keys pressed through the window's own key handler. Prints 'keys ok'."""

from __future__ import annotations

import numpy as np

from tests.support.window import glfw_window, press


def main() -> None:
    import glfw
    from sasprobe.molecule import load_default
    from sasprobe.render.app import RenderOptions, make_renderer
    from sasprobe.render.camera import Camera
    from sasprobe.render.lighting.settings import AO_MODES, AOSettings, LightingSettings
    from sasprobe.render.source import StaticSource
    from sasprobe.render.window.window_app import WindowApp

    size = (160, 120)
    opts = RenderOptions(
        size=size, lighting=LightingSettings(shadows="hard", ao=AOSettings(mode="analytic"))
    )
    with glfw_window(size, "lighting keys") as (window, ctx):

        def build(structure, effects):
            from sasprobe.render.app import build_scene

            scene = build_scene(structure, opts, effects)
            scene.light_direction = -np.array([0.45, 0.8, 0.4]) / np.linalg.norm([0.45, 0.8, 0.4])
            center, radius = scene.bounding_sphere()
            return make_renderer(
                ctx, scene, glfw.get_framebuffer_size(window), opts
            ), Camera.fitted(center, radius * 0.8, size[0] / size[1], direction=(0.2, 0.3, 1.0))

        app = WindowApp(window, ctx, StaticSource(load_default()), build, "test", opts.effects())
        app.run(frames=1)
        first = app._screenshot(glfw.get_framebuffer_size(window))
        fx = app.effects
        assert fx.shadows and fx.ambient_occlusion and not fx.soft_shadows and not fx.edge_cueing, (
            fx
        )

        for key, field in (
            (glfw.KEY_S, "shadows"),
            (glfw.KEY_V, "soft_shadows"),
            (glfw.KEY_A, "ambient_occlusion"),
            (glfw.KEY_E, "edge_cueing"),
            (glfw.KEY_G, "path_tracing"),
        ):
            before = getattr(fx, field)
            press(app, key)
            assert getattr(fx, field) != before, field
            press(app, key)
        lighting = app.renderer.lighting
        modes = [lighting.ao_mode]
        for _ in range(len(AO_MODES) - 2):
            press(app, glfw.KEY_A, glfw.MOD_SHIFT)
            modes.append(lighting.ao_mode)
        assert sorted(modes) == sorted(m for m in AO_MODES if m != "off"), modes
        press(app, glfw.KEY_A, glfw.MOD_SHIFT)
        assert lighting.ao_mode == modes[0]
        assert any("lighting: hard shadows, AO analytic" in line for line in app.text()), app.text()
        press(app, glfw.KEY_S)  # shadows off: the picture changes
        app.run(frames=1)
        second = app._screenshot(glfw.get_framebuffer_size(window))
        assert np.abs(second.astype(int) - first.astype(int)).max() > 30, (
            "switching shadows off changed nothing"
        )
        app.release()
    print("keys ok")


if __name__ == "__main__":
    main()
