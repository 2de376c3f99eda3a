"""Run by tests/test_daemon_findings_session.py under Xvfb (DISPLAY set), with a recording daemon at
$SASPROBE_TEST_PUB / $SASPROBE_TEST_CTL: a real glfw window following it. Enter (through
the window's own key handler) must drop mark 1 in the daemon's scene, the window must then
draw its numbered badge where the mark projects, and the readout must show the live
clearance line. Prints 'keys ok'."""

from __future__ import annotations

import os
import time

import numpy as np

from tests.support.window import glfw_window, press

SIZE = (320, 240)


def main() -> None:
    import glfw
    from sasprobe.protocol.client import ControlClient
    from sasprobe.render.app import RenderOptions, build_scene, initial_camera, make_renderer
    from sasprobe.render.follow.daemon_source import DaemonSource
    from sasprobe.render.window.window_app import WindowApp

    pub, ctl = os.environ["SASPROBE_TEST_PUB"], os.environ["SASPROBE_TEST_CTL"]
    opts = RenderOptions(size=SIZE)
    link = DaemonSource(pub, ctl)
    with glfw_window(SIZE, "marks") as (window, ctx):

        def build(structure, effects):
            scene = build_scene(structure, opts, effects)
            return make_renderer(
                ctx, scene, glfw.get_framebuffer_size(window), opts
            ), initial_camera(scene, opts)

        app = WindowApp(window, ctx, link, build, "test", opts.effects())
        deadline = time.monotonic() + 60
        while (
            app.renderer is None or link.subscriber.pose is None
        ) and time.monotonic() < deadline:
            app.run(frames=1)
        assert app.renderer is not None, "no structure from the daemon"
        while link.live.clearance_A is None and time.monotonic() < deadline:
            app.run(frames=1)
        assert any(line.startswith("clearance ") for line in app.text()), app.text()
        press(app, glfw.KEY_ENTER)
        while app.source.readout().note != "mark 1 dropped" and time.monotonic() < deadline:
            app.run(frames=1)
        assert app.source.readout().note == "mark 1 dropped", app.source.readout().note
        with ControlClient(ctl) as client:
            marks = client.get_scene()["marks"]
        assert len(marks) == 1 and marks[0]["id"] == 1 and marks[0]["label"] == "mark 1", marks
        while not app.renderer.scene.marks and time.monotonic() < deadline:
            app.run(frames=1)
        # The same frame with and without the marks (no new pose in between): the badge is the
        # difference.
        size = glfw.get_framebuffer_size(window)
        app.renderer.render(app.camera, output_fbo=ctx.screen)
        with_marks = app._screenshot(size)
        app.effects.marks = False
        app.renderer.render(app.camera, output_fbo=ctx.screen)
        without = app._screenshot(size)
        frame = app.renderer.last_frame
        clip = frame.viewproj @ np.array([*marks[0]["position_A"], 1.0])
        w, h = frame.size
        x, y = (
            (clip[0] / clip[3] * 0.5 + 0.5) * w,
            (0.5 - clip[1] / clip[3] * 0.5) * h,
        )  # row 0 = top
        ys, xs = np.nonzero(np.abs(with_marks.astype(int) - without.astype(int)).max(axis=2) > 8)
        assert xs.size > 100, f"the badge changed {xs.size} pixels"
        assert abs(xs.mean() - x) < 2.5 and abs(ys.mean() - y) < 2.5, (xs.mean(), ys.mean(), x, y)
        assert xs.max() - xs.min() < 24 and ys.max() - ys.min() < 24, "one badge, BADGE_PX wide"
    link.close()
    print("keys ok")


if __name__ == "__main__":
    main()
