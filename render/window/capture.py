"""What the window's capture keys write and what a click names: timestamped screenshots
(Ctrl+S), a video in real time (Ctrl+R), and the picked atom's label."""

from __future__ import annotations

import logging
import time
from datetime import datetime
from pathlib import Path

import numpy as np
from sasprobe.molecule import Structure
from sasprobe.render.output import FrameWriter

log = logging.getLogger("sasprobe")

VIDEO_FPS = 30.0


def timestamped(folder: Path, suffix: str, now: datetime | None = None) -> Path:
    """folder/sasprobe-YYYYmmdd-HHMMSS<suffix>, with -2, -3 ... when that name is taken."""
    stem = f"sasprobe-{(now or datetime.now()).strftime('%Y%m%d-%H%M%S')}"
    path, n = folder / f"{stem}{suffix}", 2
    while path.exists():
        path, n = folder / f"{stem}-{n}{suffix}", n + 1
    return path


def save_screenshot(folder: Path, image: np.ndarray) -> Path:
    path = timestamped(folder, ".png")
    FrameWriter(path, 1, VIDEO_FPS).write(image)
    return path


class PacedRecorder:
    """An MP4 of the window in real time: each drawn frame fills the 1/fps slots that passed
    while it was shown (a window on a slow renderer draws fewer frames than the video has)."""

    def __init__(self, folder: Path, fps: float = VIDEO_FPS):
        self.path = timestamped(folder, ".mp4")
        self.fps = fps
        self.writer = FrameWriter(self.path, None, fps)
        self.start = time.perf_counter()
        self.frames = 0

    def add(self, image: np.ndarray) -> None:
        h, w = image.shape[:2]
        image = image[: h - h % 2, : w - w % 2]  # H.264 wants even sizes
        due = int((time.perf_counter() - self.start) * self.fps) + 1
        for _ in range(max(due - self.frames, 1 if self.frames == 0 else 0)):
            self.writer.write(image)
            self.frames += 1

    def close(self) -> Path:
        self.writer.close()
        return self.path


class WindowCapture:
    """The window's Ctrl+S and Ctrl+R: what is due, what is being recorded, what was written."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.recorder: PacedRecorder | None = None
        self.screenshot_due = False  # taken after the next frame is drawn, before it is shown
        self.saved: list[Path] = []  # screenshots and videos written, in order
        self.message = ""  # the last capture's line in the readout

    @property
    def wants_frame(self) -> bool:
        return self.screenshot_due or self.recorder is not None

    def toggle_recording(self) -> None:
        if self.recorder is None:
            self.recorder = PacedRecorder(self.folder)
            self.message = f"recording {self.recorder.path.name} (Ctrl+R stops)"
        else:
            path = self.recorder.close()
            self.recorder = None
            self._wrote(path)

    def take(self, image: np.ndarray) -> None:
        """The frame just drawn: the due screenshot, and the video's next frames."""
        if self.screenshot_due:
            self.screenshot_due = False
            self._wrote(save_screenshot(self.folder, image))
        if self.recorder is not None:
            self.recorder.add(image)

    def close(self) -> None:
        if self.recorder is not None:
            self.toggle_recording()  # finish the video

    def _wrote(self, path: Path) -> None:
        self.saved.append(path)
        self.message = f"saved {path}"
        log.info("wrote %s", path)


def atom_label(structure: Structure, atom: int, sas_area: float) -> str:
    """What a click on an atom shows: chain, residue name and number, atom name, element,
    the atom's exposed SAS area."""
    s = structure
    number = f"{int(s.residue_numbers[atom])}{s.insertion_codes[atom]}"
    return (
        f"chain {s.chain_ids[atom]}  {s.residue_names[atom]} {number}  "
        f"{s.atom_names[atom]} ({s.elements[atom]})"
        f"  SAS {sas_area:.1f} Å²"
    )
