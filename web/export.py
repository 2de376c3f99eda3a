"""A recorded session as one self-contained HTML file (`sasprobe replay FILE --html OUT`): the
page's own modules, the structure, the poses decimated to what a screen shows, the scenes,
the marks and the findings' summary, playing offline from `file://`.

The poses are sampled as the video is (protocol/playback.py): frame k, at FPS frames a
second, shows the newest pose published at or before the first pose's time + k/FPS, with
the scene and the structure in force then. Packets (web/packets.py) and the list of scenes
(a long session turns its view often) travel gzip-compressed and base64-encoded inside a
JSON block; the page's modules are `data:` URLs its import map
names, and its Content-Security-Policy lets it load nothing from anywhere.
"""

from __future__ import annotations

import base64
import gzip
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
from sasprobe.molecule import parse_structure
from sasprobe.molecule.residues import touched_label
from sasprobe.protocol.playback import frame_count, pose_time_range, recorded_frames
from sasprobe.web.packets import (
    colors_packet,
    effective_scheme,
    hello,
    packet,
    structure_packet,
)
from sasprobe.web.page_files import REPLAY_PAGE, modules, page_files

from sasprobe.common.errors import UserError

FPS = 60.0  # frames a second the poses are decimated to


def blob(data: bytes) -> str:
    """Bytes (a packet, or the scenes' JSON) as the page reads them: gzip, then base64."""
    return base64.b64encode(gzip.compress(data, compresslevel=9, mtime=0)).decode("ascii")


class _Session:
    """What the frames of a recording add up to, gathered in one pass."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.structures: list[dict] = []  # {"name", "sha256", "packet"}
        self.parsed: dict[str, object] = {}  # sha256 -> Structure
        self.colors: dict[tuple, int] = {}  # (sha256, scheme, radius) -> index in color_packets
        self.color_packets: list[str] = []
        self.scenes: list[dict] = []  # {"scene", "colors": index}
        self.scene_index: dict[tuple, int] = {}
        self.labels: dict[str, dict[str, str]] = {}  # sha256 -> atom -> label
        self.marks: dict[tuple, dict] = {}  # (sha256, id) -> {"id", "label", "t_s"}
        self.rows: dict[str, list] = {
            k: []
            for k in (
                "t_s",
                "seq",
                "proxy",
                "goal",
                "force",
                "cube",
                "touched",
                "flags",
                "structure",
                "scene",
            )
        }

    def structure(self, frame) -> int:
        sha = frame.structure_sha256
        for k, s in enumerate(self.structures):
            if s["sha256"] == sha:
                return k
        if frame.structure_file is None:
            raise UserError(f"{self.path}: structure {sha[:12]} is not attached to the recording")
        name, data, keep_water = frame.structure_file
        structure = parse_structure(
            data, name=name, source=f"{self.path}:{name}", keep_water=keep_water
        )
        self.parsed[sha] = structure
        self.labels[sha] = {}
        self.structures.append(
            {"name": structure.name, "sha256": sha, "packet": blob(structure_packet(structure))}
        )
        return len(self.structures) - 1

    def scene(self, frame, t_s: float) -> int:
        scene = frame.scene
        key = (scene.get("revision"), scene["structure"]["sha256"])
        index = self.scene_index.get(key)
        if index is not None:
            return index
        structure = self.parsed[frame.structure_sha256]
        scheme = effective_scheme(structure, scene)
        radius = float(scene["probe_radius_A"]) if scheme == "sas" else None
        ckey = (structure.sha256, scheme, radius)
        if ckey not in self.colors:
            self.colors[ckey] = len(self.color_packets)
            self.color_packets.append(blob(colors_packet(structure, scheme, radius)))
        for mark in scene.get("marks", []):
            self.marks.setdefault(
                (structure.sha256, mark["id"]),
                {"id": mark["id"], "label": mark["label"], "t_s": t_s},
            )
        self.scene_index[key] = len(self.scenes)
        self.scenes.append({"scene": scene, "colors": self.colors[ckey]})
        return self.scene_index[key]

    def add(self, frame, t_s: float) -> None:
        pose = frame.pose
        structure = self.structure(frame)
        scene = self.scene(frame, t_s)
        sha = frame.structure_sha256
        atom = int(pose.touched_atom)
        if atom >= 0 and str(atom) not in self.labels[sha]:
            label = touched_label(self.parsed[sha], atom)
            if label is not None:
                self.labels[sha][str(atom)] = label
        r = self.rows
        r["t_s"].append(t_s)
        r["seq"].append(pose.seq)
        r["proxy"].append(pose.proxy_A)
        r["goal"].append(pose.goal_A)
        r["force"].append(pose.force_N)
        r["cube"].append([*pose.cube_center_A, pose.cube_half_A])
        r["touched"].append(atom)
        r["flags"].append(pose.flags)
        r["structure"].append(structure)
        r["scene"].append(scene)

    def poses(self) -> bytes:
        r = self.rows
        f4 = {k: np.asarray(r[k], dtype=np.float32) for k in ("proxy", "goal", "force", "cube")}
        return packet(
            {"kind": "poses", "fps": FPS, "rows": len(r["t_s"])},
            {
                "t_s": np.asarray(r["t_s"], dtype=np.float64),
                "seq": np.asarray(r["seq"], dtype=np.float64),
                **f4,
                "touched": np.asarray(r["touched"], dtype=np.int32),
                "flags": np.asarray(r["flags"], dtype=np.uint16),
                "structure": np.asarray(r["structure"], dtype=np.uint16),
                "scene": np.asarray(r["scene"], dtype=np.uint32),
            },
        )


def session_html(
    path: Path,
    findings: list[str] | None = None,
    progress: Callable[[int], None] | None = None,
) -> str:
    """The self-contained page of a recording; `findings`: the summary's lines to show."""
    time_range = pose_time_range(path)
    if time_range is None:
        raise UserError(f"{path}: no recorded poses to show")
    session = _Session(path)
    for frame in recorded_frames(path, FPS, time_range):
        session.add(frame, frame.index / FPS)
        if progress is not None:
            progress(1)
    data = {
        "hello": hello(),
        "recording": Path(path).name,
        "duration_s": (time_range[1] - time_range[0]) / 1e9,
        "structures": session.structures,
        "colors": session.color_packets,
        "scenes": blob(json.dumps(session.scenes, allow_nan=False).encode()),
        "labels": [session.labels[s["sha256"]] for s in session.structures],
        "marks": sorted(session.marks.values(), key=lambda m: m["t_s"]),
        "poses": blob(session.poses()),
        "findings": findings or [],
    }
    return page(data)


def frames_to_write(path: Path) -> int:
    """How many frames session_html samples from a recording (for a progress bar)."""
    time_range = pose_time_range(path)
    return frame_count(time_range, FPS) if time_range else 0


def page(data: dict) -> str:
    """replay.html with the page's style, its modules as data: URLs and the session inlined."""
    files = page_files()
    imports = {
        f"sasprobe/{name}": "data:text/javascript;base64," + base64.b64encode(source).decode()
        for name, source in modules().items()
    }
    inline = {
        "@@STYLE@@": files["style.css"].decode(),
        "@@IMPORTMAP@@": json.dumps({"imports": imports}),
        "@@SESSION@@": json.dumps(data, separators=(",", ":"), allow_nan=False),
        "@@TITLE@@": _escape(f"sasprobe: {data['recording']}"),
    }
    html = files[REPLAY_PAGE].decode()
    for key, value in inline.items():
        html = html.replace(key, value.replace("</", "<\\/"))
    return html


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
