"""Run by tests/test_devices_workspace_session.py under Xvfb (DISPLAY set): a real glfw window
following a real daemon (simulated arm, sim:sweep). Through the window's own handlers: it starts in
the workspace view; a drag turns the daemon's workspace (its scene's rotation); Space held
clutches the daemon's probe, released lets go; Home recentres the cube on the probe; Tab
shows the overview and back; the readout names the force against the ratings. Prints
'keys ok'."""

from __future__ import annotations

import time

import numpy as np

from tests.support.daemon_process import DaemonProcess
from tests.support.window import glfw_window, press

SIZE = (240, 180)


def main() -> None:
    import glfw
    from sasprobe.protocol.client import ControlClient, Subscriber
    from sasprobe.protocol.pose import FLAG_CLUTCHED
    from sasprobe.render.app import RenderOptions, build_scene, initial_camera, make_renderer
    from sasprobe.render.follow.daemon_source import DaemonSource
    from sasprobe.render.window.window_app import WindowApp
    from sasprobe.render.workspace_view import OVERVIEW, WORKSPACE

    with (
        DaemonProcess("--seconds", "120", device="sim:sweep") as daemon,
        glfw_window(SIZE, "workspace keys") as (window, ctx),
    ):
        opts = RenderOptions(size=SIZE, connect=daemon.pub, control=daemon.ctl)
        link = DaemonSource(daemon.pub, daemon.ctl)
        watch = Subscriber(daemon.pub)
        control = ControlClient(daemon.ctl)

        def build(structure, effects):
            scene = build_scene(structure, opts, effects)
            return make_renderer(
                ctx, scene, glfw.get_framebuffer_size(window), opts
            ), initial_camera(scene, opts)

        app = WindowApp(window, ctx, link, build, "test", opts.effects(), opts.start_view)

        def until(condition, what: str, timeout: float = 20.0) -> None:
            end = time.monotonic() + timeout
            while time.monotonic() < end:
                app.run(frames=1)
                watch.poll()
                if condition():
                    return
            raise AssertionError(f"timed out waiting for {what}")

        until(lambda: app._workspace_camera() is not None, "the workspace view")
        assert app.view.mode == WORKSPACE and app.effects.probe_plane
        camera = app._workspace_camera()
        assert np.allclose(camera.basis(), np.eye(3)), (
            "device x, y, z = screen right, up, toward the viewer"
        )

        app._on_button(window, glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
        app._last_pos = (SIZE[0] * 0.5, SIZE[1] * 0.5)
        app._on_cursor(
            window, SIZE[0] * 0.8, SIZE[1] * 0.5
        )  # drag right: the molecule turns about the screen's y
        app._on_button(window, glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)

        def turned() -> bool:
            r = np.array(control.get_scene()["view"]["rotation"])
            return not np.allclose(r, np.eye(3)) and np.allclose(
                r[:, 1], [0.0, 1.0, 0.0], atol=1e-6
            )

        until(turned, "the daemon's workspace to turn")
        until(
            lambda: np.allclose(
                app._workspace_camera().basis(),
                np.array(control.get_scene()["view"]["rotation"]),
                atol=1e-9,
            ),
            "the camera to follow the daemon's turn",
        )

        app._on_key(window, glfw.KEY_SPACE, glfw.get_key_scancode(glfw.KEY_SPACE), glfw.PRESS, 0)
        until(lambda: watch.pose is not None and watch.pose.has(FLAG_CLUTCHED), "the clutch")
        until(lambda: any("CLUTCH" in line for line in app.text()), "the readout to say CLUTCH")
        held = watch.pose.seq
        until(lambda: watch.pose.seq > held + 1500, "1.5 s with Space down", timeout=30)
        assert watch.pose.has(FLAG_CLUTCHED), "the window renews the clutch while Space is down"
        app._on_key(window, glfw.KEY_SPACE, glfw.get_key_scancode(glfw.KEY_SPACE), glfw.RELEASE, 0)
        until(lambda: not watch.pose.has(FLAG_CLUTCHED), "the clutch to let go")

        probe = watch.pose.proxy_A.copy()
        assert (
            np.linalg.norm(watch.pose.cube_center_A - probe) > 1.5
        )  # the probe hovers above the cube's centre
        press(app, glfw.KEY_HOME)
        until(
            lambda: np.linalg.norm(watch.pose.cube_center_A - probe) < 1.0,
            "the cube to centre on the probe",
        )

        press(app, glfw.KEY_TAB)
        assert (
            app.view.mode == OVERVIEW
            and not app.effects.probe_plane
            and app._workspace_camera() is None
        )
        # The overview frames what it shows of the whole molecule (the trace beyond the cube, the
        # cube and its atoms), and the probe, and fills the picture.
        scene = app.renderer.scene
        trace = scene.structure.positions[np.concatenate(scene.structure.backbone)]
        points = np.vstack([trace, scene.nav_cube.corners(), scene.probe.center])
        clip = (
            np.column_stack([points, np.ones(len(points))])
            @ (app.camera.projection(SIZE[0] / SIZE[1]) @ app.camera.view()).T
        )
        ndc = clip[:, :2] / clip[:, 3:]
        assert np.all(clip[:, 3] > 0) and np.abs(ndc).max() <= 1.0, (
            "the overview frames the whole molecule"
        )
        assert (ndc.max(axis=0) - ndc.min(axis=0)).max() > 1.2, "the overview fills the picture"
        press(app, glfw.KEY_TAB)
        assert app.view.mode == WORKSPACE and app._workspace_camera() is not None
        text = "\n".join(app.text())
        assert "continuous 0.88 N, peak 3.30 N" in text and "workspace view" in text, text

        press(app, glfw.KEY_Q)
        app.release()
        link.close()
        watch.close()
        control.close()
    print("keys ok")


if __name__ == "__main__":
    main()
