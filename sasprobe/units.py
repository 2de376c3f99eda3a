"""argparse types for physical quantities: one clear line for a bad value."""

from __future__ import annotations

import argparse
import math

MAX_PROBE_RADIUS = 10.0  # Å; larger "probes" are not a solvent any more


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
    value = positive_float(text)
    if value > MAX_PROBE_RADIUS:
        raise argparse.ArgumentTypeError(f"probe radius {value:g} Å is absurd (at most {MAX_PROBE_RADIUS:g} Å)")
    return value
