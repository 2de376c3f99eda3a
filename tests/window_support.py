"""Shared by the window check scripts (run under Xvfb in their own process): a glfw window
that is always torn down, and key presses through the window's own handler."""

from __future__ import annotations

from contextlib import contextmanager


@contextmanager
def glfw_window(size: tuple[int, int], title: str):
    """(window, moderngl context) of a real window; destroyed and glfw terminated afterwards."""
    import glfw

    from sasprobe.render.gl.context import create_window

    window, ctx = create_window(size, title)
    try:
        yield window, ctx
    finally:
        glfw.destroy_window(window)
        glfw.terminate()


def press(app, key: int, mods: int = 0) -> None:
    """A key press (with modifier bits, e.g. glfw.MOD_CONTROL) as glfw delivers it to the WindowApp."""
    import glfw

    app._on_key(app.window, key, glfw.get_key_scancode(key), glfw.PRESS, mods)
