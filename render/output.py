"""Where rendered frames go: one PNG, numbered PNGs, or an MP4 (imageio-ffmpeg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sasprobe.common.errors import UserError

VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi")
IMAGE_SUFFIXES = (".png",)


def check_out_path(path: Path, frames: int | None) -> None:
    """Validate --out before any rendering starts (one clear line on a bad path)."""
    suffix = path.suffix.lower()
    if suffix not in VIDEO_SUFFIXES + IMAGE_SUFFIXES:
        raise UserError(f"--out {path}: expected a .png image or an .mp4 video")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise UserError(f"--out {path}: folder {parent} does not exist")


class FrameWriter:
    """Writes frames as they come. PNG with one frame: the path itself; with several:
    NAME_0000.png, NAME_0001.png, ... (or the path's own %d pattern). Video: one file."""

    def __init__(self, path: Path, total_frames: int | None, fps: float):
        self.path = Path(path)
        self.total = total_frames
        self.fps = fps
        self.count = 0
        self.is_video = self.path.suffix.lower() in VIDEO_SUFFIXES
        self._writer = None
        self.written: list[Path] = []

    def _png_path(self, index: int) -> Path:
        name = str(self.path)
        if "%" in name:
            return Path(name % index)
        if self.total == 1:
            return self.path
        return self.path.with_name(f"{self.path.stem}_{index:04d}{self.path.suffix}")

    def write(self, image: np.ndarray) -> None:
        import imageio.v2 as imageio

        try:
            if self.is_video:
                if self._writer is None:
                    h, w = image.shape[:2]
                    if w % 2 or h % 2:
                        raise UserError(
                            f"--out {self.path}: video frames need an even width and height, "
                            f"got {w}x{h}"
                        )
                    self._writer = imageio.get_writer(
                        str(self.path),
                        fps=self.fps,
                        codec="libx264",
                        quality=8,
                        macro_block_size=2,
                        pixelformat="yuv420p",
                    )
                    self.written.append(self.path)
                self._writer.append_data(image)
            else:
                target = self._png_path(self.count)
                imageio.imwrite(target, image)
                self.written.append(target)
        except OSError as exc:
            raise UserError(f"--out {self.path}: cannot write ({exc.strerror or exc})") from None
        self.count += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
