"""OpenGL contexts for the renderer: headless (EGL) or a glfw window.

Every failure a user can meet (no EGL, no display, too old a GL) ends in a
GLUnavailable: one line saying what is missing.
"""

from __future__ import annotations

import os

from sasprobe.common.errors import UserError

REQUIRED_GL = 410  # OpenGL 4.1 core: geometry shaders, conservative depth via extension
REQUIRED_GL_TEXT = "4.1"


class GLUnavailable(UserError):
    """No usable OpenGL context (one line: what is missing and what to try)."""


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def check_version(ctx) -> None:
    """Raise GLUnavailable when a context is older than the renderer needs."""
    if ctx.version_code < REQUIRED_GL:
        info = ctx.info
        raise GLUnavailable(
            f"OpenGL {REQUIRED_GL_TEXT} core is required, but "
            f"{info.get('GL_RENDERER', 'this driver')} "
            f"offers only {info.get('GL_VERSION', ctx.version_code)}"
        )


def create_headless_context():
    """A standalone EGL context (Mesa's llvmpipe works without a GPU)."""
    import moderngl

    try:
        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception as exc:  # moderngl raises bare Exception for EGL failures
        raise GLUnavailable(
            f"no headless OpenGL: an EGL context could not be created ({_first_line(exc)}); "
            "install Mesa's EGL and DRI drivers (libegl1, libgl1-mesa-dri) or a GPU driver"
        ) from None
    try:
        check_version(ctx)
    except GLUnavailable:
        ctx.release()
        raise
    return ctx


def display_available() -> bool:
    """Whether a window can be expected to open (an X11 or Wayland display is named)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def create_window(size: tuple[int, int], title: str):
    """A visible glfw window with a current OpenGL 4.1+ core context: (window, moderngl ctx)."""
    import glfw
    import moderngl

    if not glfw.init():
        raise GLUnavailable(
            "cannot open a window: glfw could not initialise (no display?); use --headless"
        )
    glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4)
    glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 1)
    glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
    glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
    glfw.window_hint(glfw.SAMPLES, 0)
    window = glfw.create_window(size[0], size[1], title, None, None)
    if not window:
        glfw.terminate()
        raise GLUnavailable(
            f"cannot open a window with an OpenGL {REQUIRED_GL_TEXT} core context on this display; "
            "use --headless"
        )
    glfw.make_context_current(window)
    glfw.swap_interval(0)
    try:
        ctx = moderngl.create_context()
        check_version(ctx)
    except GLUnavailable:
        glfw.terminate()
        raise
    except Exception as exc:
        glfw.terminate()
        raise GLUnavailable(
            f"cannot use the window's OpenGL context ({_first_line(exc)})"
        ) from None
    return window, ctx
