"""The demo's watching (sasprobe/cli/demo.py) on stand-ins for its children and their
sockets: when the measured window of summary.json's `haptics` begins."""

from __future__ import annotations


def test_the_measured_window_begins_with_the_first_frame(tmp_path, monkeypatch):
    """The daemon's statistics are reset (the window of summary.json's `haptics`) once the
    renderer's first frame is in the video, not when the renderer starts: its start-up
    (imports, GL context, the structure) is not the demo proper. The demo's watching runs
    on stand-ins for the renderer, the daemon and their sockets."""
    from sasprobe.cli import demo as demo_module

    session = demo_module.DemoSession(demo_module.DemoOptions(out=tmp_path))
    resets: list[bool] = []  # for each reset: was the first frame in the video yet?

    class Renderer:
        """Alive for 20 polls; its first frame lands in the video at the 10th."""

        def __init__(self, *args, **kwargs) -> None:
            self.polls = 0

        def alive(self) -> bool:
            self.polls += 1
            if self.polls == 10:
                session.video.write_bytes(b"first frame")
            return self.polls < 20

        def error_line(self) -> str:
            return ""

    class Daemon:
        def alive(self) -> bool:
            return True

    class Control:
        def status(self, reset_stats: bool = False) -> dict:
            if reset_stats:
                resets.append(session.video.exists())
            return {"loop": {"recent": {"rate_hz": 1000.0}}}

        def close(self) -> None:
            pass

    class Monitor:
        def poll(self) -> None:
            pass

        def last_force(self) -> None:
            return None

        def contact_fraction(self) -> None:
            return None

        def close(self) -> None:
            pass

    monkeypatch.setattr(demo_module, "Child", Renderer)
    monkeypatch.setattr(demo_module, "POLL_S", 0.001)
    session.daemon, session.control, session.monitor = Daemon(), Control(), Monitor()
    try:
        session.start_renderer(headless=True, seconds=1.0)
        session.watch(headless=True, seconds=1.0)
    finally:
        session.close()
    assert resets == [True]
