"""The readout's live lines, as text: the haptic rate and force, the touched atom, the
clutch, the room at the probe. The window draws them over its frame (render/window/) and a
headless run following a daemon over every picture it writes (render/headless.py), so a
picture says where on the molecule the probe is, as the window does."""

from __future__ import annotations

import numpy as np
from sasprobe.render.source import Readout
from sasprobe.render.text import text_image

MARGIN = 8  # pixels between the frame's top-left corner and the text's box


def force_text(readout: Readout) -> str:
    """'force 0.42 N (continuous 0.88 N, peak 3.30 N)', or what of it is known."""
    if readout.force_n is None:
        return "force -"
    text = f"force {readout.force_n:.2f} N"
    if readout.continuous_force_n is not None and readout.peak_force_n is not None:
        over = "  ABOVE CONTINUOUS" if readout.force_n > readout.continuous_force_n else ""
        ratings = (
            f"continuous {readout.continuous_force_n:.2f} N, peak {readout.peak_force_n:.2f} N"
        )
        text += f" ({ratings}){over}"
    return text


def clearance_line(ro: Readout) -> str:
    """Room at the probe (Å): clearance at its centre, passage across its path, narrowest so far."""
    passage = "open" if ro.passage_A is None else f"{ro.passage_A:.2f} Å"
    bottleneck = "-" if ro.bottleneck_A is None else f"{ro.bottleneck_A:.2f} Å"
    return f"clearance {ro.clearance_A:.2f} Å   passage {passage}   bottleneck {bottleneck}"


def readout_lines(ro: Readout) -> list[str]:
    """The live state's lines, in the order the window shows them."""
    lines = [ro.status] if ro.status else []
    if ro.haptic_hz is not None:
        lines.append(f"haptic {ro.haptic_hz:6.0f} Hz   {force_text(ro)}")
        lines.append(f"touching {ro.touched}" if ro.touched else "not touching")
        lines += [
            state
            for state, on in (
                ("CLUTCH (Space/button held)", ro.clutched),
                ("cube drifting", ro.drifting),
            )
            if on
        ]
    if ro.clearance_A is not None:
        lines.append(clearance_line(ro))
    if ro.note:
        lines.append(ro.note)
    return lines


def draw_text(image: np.ndarray, lines: list[str]) -> np.ndarray:
    """The RGB image (row 0 = top) with the lines in their translucent box at its top-left
    corner, as the window's overlay draws them; the box is cut where the image ends."""
    if not lines:
        return image
    box = text_image(lines).astype(np.float32)
    height = min(box.shape[0], image.shape[0] - MARGIN)
    width = min(box.shape[1], image.shape[1] - MARGIN)
    if height <= 0 or width <= 0:
        return image
    box = box[:height, :width]
    alpha = box[..., 3:] / 255.0
    out = image.copy()
    under = out[MARGIN : MARGIN + height, MARGIN : MARGIN + width].astype(np.float32)
    blended = box[..., :3] * alpha + under * (1.0 - alpha)
    out[MARGIN : MARGIN + height, MARGIN : MARGIN + width] = np.rint(blended).astype(np.uint8)
    return out
