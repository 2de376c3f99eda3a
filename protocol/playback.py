"""A recorded session sampled at a frame rate: what a video (`replay --video`) or a web page
(`replay --html`) shows at each of its frames.

Frame k stands for the moment t0 + k/fps, where t0 is the first recorded pose; it shows the
newest pose published at or before that moment, with the scene (probe radius, clip planes,
lights, cube) and the structure in force then. Everything comes from the recording itself
(the structure is its attachment), read in one pass in file order through
protocol/recording.py, a block of ticks at a time, so a long session needs no more memory
than a short one.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sasprobe.protocol.pose import Pose
from sasprobe.protocol.recording import TICKS_TOPIC, Recording
from sasprobe.protocol.ticks import TickBlock, ticks_span


@dataclass
class RecordedFrame:
    index: int  # frame k stands for the first pose's time + k/fps (recording clock)
    structure_sha256: str  # the structure in force (the scene's)
    # Its name, attached bytes and keep_water (None: not attached)
    structure_file: tuple[str, bytes, bool] | None
    scene: dict  # the scene message in force
    pose: Pose  # the newest pose published at or before that moment


def pose_time_range(path: Path) -> tuple[int, int] | None:
    """First and last pose log time of a recording (ns), None without poses."""
    first = last = None
    for item in Recording(path).items(decode=False):
        if item.topic == TICKS_TOPIC:
            count, _, _, lo, hi = ticks_span(item.raw)
            if count:
                first = lo if first is None else first
                last = hi
        elif item.topic == "pose":  # the first recording format: one message per pose
            first = item.log_time if first is None else first
            last = item.log_time
    return None if first is None else (first, last)


def frame_count(time_range: tuple[int, int], fps: float) -> int:
    """Frames at 1/fps steps from the first pose up to and including the last one."""
    first, last = time_range
    return int((last - first) * fps // 1_000_000_000) + 1


def recorded_frames(
    path: Path, fps: float, time_range: tuple[int, int] | None = None
) -> Iterator[RecordedFrame]:
    """The state to draw for every video frame, in order."""
    time_range = time_range or pose_time_range(path)
    if time_range is None:
        return
    t0, n = time_range[0], frame_count(time_range, fps)
    files: dict[str, tuple[str, bytes]] = {}
    keep_water: dict[str, bool] = {}
    k = 0
    scene = pose = None

    def frame() -> RecordedFrame:
        sha = scene["structure"]["sha256"]
        attached = (*files[sha], keep_water.get(sha, False)) if sha in files else None
        return RecordedFrame(k, sha, attached, scene, pose)

    for item in Recording(path).stream():
        if isinstance(item, TickBlock):
            # Frames due before the block's last pose show the newest pose at or before them.
            log = item.log_ns
            while k < n and scene is not None:
                due = t0 + k * 1e9 / fps
                if due >= log[-1]:
                    break
                row = int(np.searchsorted(log, due, side="right")) - 1
                if row >= 0:
                    pose = item.pose_at(row)
                if pose is None:
                    break
                yield frame()
                k += 1
            pose = item.pose_at(len(item) - 1)
        elif item.topic == "attachment":
            files[item.data["sha256"]] = (item.data["name"], item.raw)
        elif item.topic == "control" and item.data.get("cmd") in ("start", "load"):
            args = item.data.get("args", {})
            keep_water[args.get("structure_sha256") or args.get("sha256")] = bool(
                args.get("keep_water", False)
            )
        elif item.topic == "scene":
            scene = item.data
    while k < n and pose is not None and scene is not None:
        yield frame()
        k += 1
