"""Shared by the window check scripts (run under Xvfb in their own process): a glfw window
that is always torn down, and key presses through the window's own handler."""

from __future__ import annotations

import ctypes
import ctypes.util
from contextlib import contextmanager

import numpy as np


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
    """A key press (with modifier bits, e.g. glfw.MOD_CONTROL) as glfw delivers it to the
    WindowApp."""
    import glfw

    app._on_key(app.window, key, glfw.get_key_scancode(key), glfw.PRESS, mods)


class _XImage(ctypes.Structure):
    _fields_ = [
        ("width", ctypes.c_int),
        ("height", ctypes.c_int),
        ("xoffset", ctypes.c_int),
        ("format", ctypes.c_int),
        ("data", ctypes.c_void_p),
        ("byte_order", ctypes.c_int),
        ("bitmap_unit", ctypes.c_int),
        ("bitmap_bit_order", ctypes.c_int),
        ("bitmap_pad", ctypes.c_int),
        ("depth", ctypes.c_int),
        ("bytes_per_line", ctypes.c_int),
        ("bits_per_pixel", ctypes.c_int),
    ]


def _xlib():
    lib = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
    lib.XOpenDisplay.restype = ctypes.c_void_p
    lib.XOpenDisplay.argtypes = [ctypes.c_char_p]
    lib.XDefaultRootWindow.restype = ctypes.c_ulong
    lib.XDefaultRootWindow.argtypes = [ctypes.c_void_p]
    lib.XGetImage.restype = ctypes.POINTER(_XImage)
    lib.XGetImage.argtypes = [
        ctypes.c_void_p,
        ctypes.c_ulong,
        ctypes.c_int,
        ctypes.c_int,
        ctypes.c_uint,
        ctypes.c_uint,
        ctypes.c_ulong,
        ctypes.c_int,
    ]
    lib.XCloseDisplay.argtypes = [ctypes.c_void_p]
    lib.XSync.argtypes = [ctypes.c_void_p, ctypes.c_int]
    return lib


def x_image(dpy, drawable: int, width: int, height: int) -> np.ndarray:
    """Pixels of an X drawable through Xlib's XGetImage (H, W, 3 uint8): what the X server
    holds, independent of GL."""
    lib = _xlib()
    lib.XSync(dpy, 0)
    img = lib.XGetImage(dpy, drawable, 0, 0, width, height, 0xFFFFFFFF, 2).contents
    assert img.bits_per_pixel == 32, img.bits_per_pixel
    raw = ctypes.string_at(img.data, img.bytes_per_line * img.height)
    pixels = np.frombuffer(raw, dtype=np.uint8).reshape(img.height, img.bytes_per_line // 4, 4)
    return pixels[:, : img.width, 2::-1].copy()  # BGRX -> RGB


def x_screenshot(display: str) -> np.ndarray:
    """The root window of an X display (H, W, 3 uint8)."""
    from tests.conftest import X_SCREEN

    lib = _xlib()
    dpy = lib.XOpenDisplay(display.encode())
    assert dpy, f"cannot open X display {display}"
    try:
        return x_image(dpy, lib.XDefaultRootWindow(dpy), *X_SCREEN)
    finally:
        lib.XCloseDisplay(dpy)


def x_window_image(window) -> np.ndarray:
    """What the X server shows of a glfw window (after swap_buffers)."""
    import glfw

    w, h = glfw.get_window_size(window)
    dpy = glfw.get_x11_display()
    return x_image(
        dpy if isinstance(dpy, ctypes.c_void_p) else ctypes.c_void_p(dpy),
        glfw.get_x11_window(window),
        w,
        h,
    )
