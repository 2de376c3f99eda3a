"""argparse types the commands share (quantities, image sizes): one clear line for a bad value."""

from __future__ import annotations

import argparse
import math

MAX_IMAGE_SIZE = 8192  # pixels a side


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be a positive finite number")
    return value


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"'{text}' must be at least 1")
    return value


def probe_radius(text: str) -> float:
    from sasprobe.molecule.probe import check_probe_radius

    value = positive_float(text)
    try:
        return check_probe_radius(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def size_type(text: str) -> tuple[int, int]:
    """WIDTHxHEIGHT in pixels."""
    parts = text.lower().split("x")
    try:
        w, h = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not WIDTHxHEIGHT (e.g. 1280x720)") from None
    if not (16 <= w <= MAX_IMAGE_SIZE and 16 <= h <= MAX_IMAGE_SIZE):
        raise argparse.ArgumentTypeError(
            f"'{text}': width and height must be 16..{MAX_IMAGE_SIZE} pixels"
        )
    return w, h


def colour_type(text: str) -> tuple[float, float, float]:
    """A colour: a CSS name (white, black, lightgrey, ...), #RRGGBB, or R,G,B in 0..1."""
    if "," in text:
        try:
            rgb = tuple(float(v) for v in text.split(","))
        except ValueError:
            rgb = ()
        if len(rgb) != 3 or not all(0.0 <= v <= 1.0 for v in rgb):
            raise argparse.ArgumentTypeError(f"'{text}': R,G,B needs three numbers from 0 to 1")
        return rgb  # type: ignore[return-value]
    from PIL import ImageColor

    try:
        r, g, b = ImageColor.getrgb(text)[:3]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"'{text}' is not a colour (a name such as white, #RRGGBB, or R,G,B in 0..1)"
        ) from None
    return (r / 255.0, g / 255.0, b / 255.0)
