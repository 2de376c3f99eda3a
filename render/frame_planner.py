"""The frame planner: the one place that decides what a frame redraws, so the passes hold
no caching policy of their own (they take the plan with the frame, Frame.plan).

A frame is two layers: the *molecule layer* (the G-buffer of the atoms and the backbone
trace, and every lighting term that does not depend on the probe) and the probe's. The
molecule layer's key is everything the renderer draws it from except the probe: the scene
field by field, the camera, the size, the planes and cube in effect and every pass's
`state()`, so a field added to any of them is keyed without being listed.

Each frame's plan says what it does with the molecule layer (FrameKind) and, for each
footprint name, the region a pass must redo: passes say where the probe can change what
they draw (Pass.footprint), and a region is that footprint now and last frame (what the
probe covered there is put back). docs/rendering.md explains the four kinds.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from sasprobe.molecule import Structure
from sasprobe.render.gl.gbuffer_stash import GBufferStash
from sasprobe.render.rects import Rect, full_rect, points_rect, union_rect


class FrameKind(Enum):
    """What a frame does with the molecule layer (FramePlan.kind)."""

    # The last frame's layer holds: its passes do not run, and the G-buffer gets back, from
    # a stash, what the probe covered.
    KEPT = "kept"
    # Only the probe plane moved, with a navigation cube: the trace and the background
    # beyond the cube are kept (the trace is drawn only where the eye's ray misses the cube),
    # and the cube's atoms are drawn anew within its rectangle (FramePlan.redraw).
    ATOMS_REDRAWN = "atoms redrawn"
    # The key changed: the layer is drawn anew and kept.
    DRAWN = "drawn"
    # The key changed on the last frame too (a turning camera, a drifting cube): the frame
    # is drawn whole with the probe and nothing is kept, since a layer kept now would most
    # likely go unused and drawing it apart costs more than a whole frame.
    WHOLE = "whole"


EVERYWHERE = "everywhere"  # a footprint covering the whole frame

# Footprint names several passes share (a pass's own are prefixed with its name).
LIT = "lit"  # lit surfaces whose colour the probe changes (the shading pass shades them again)
LIT_BACKGROUND = "lit background"  # background pixels whose colour the probe changes
OVERLAY = "overlay"  # what is drawn over the lit picture (the probe's cues)


def state_key(value, skip: tuple[str, ...] = ()):
    """A comparable snapshot of plain state. Dataclasses go field by field (the names in
    `skip` are left out at the top level only), numpy arrays by dtype, shape and bytes,
    containers element by element. A Structure counts by identity: structures are never
    changed in place (a new one is loaded). Anything else counts by its type and identity,
    so replacing it changes the key."""
    if value is None or isinstance(value, (bool, int, float, str, bytes)):
        return value
    if isinstance(value, Structure):
        return ("Structure", id(value))
    if isinstance(value, np.ndarray):
        return ("array", value.dtype.str, value.shape, value.tobytes())
    if isinstance(value, np.generic):
        return value.item()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        # Settings: their keys are found once (a few hundred fields a frame)
        if not skip and _frozen(value):
            key = _FROZEN_KEYS.get(value)
            if key is None:
                if len(_FROZEN_KEYS) >= FROZEN_KEYS_KEPT:
                    _FROZEN_KEYS.clear()
                key = _FROZEN_KEYS[value] = _dataclass_key(value, skip)
            return key
        return _dataclass_key(value, skip)
    if isinstance(value, (list, tuple)):
        return tuple(state_key(v) for v in value)
    if isinstance(value, dict):
        return tuple(sorted((str(k), state_key(v)) for k, v in value.items()))
    return (type(value).__name__, id(value))


FROZEN_KEYS_KEPT = 256
_FROZEN_KEYS: dict = {}  # frozen, hashable dataclass -> its key (equal values, equal keys)


def _dataclass_key(value, skip: tuple[str, ...]) -> tuple:
    return (type(value).__name__,) + tuple(
        (f.name, state_key(getattr(value, f.name)))
        for f in dataclasses.fields(value)
        if f.name not in skip
    )


def _frozen(value) -> bool:
    """Whether a dataclass instance is frozen and hashable: then none of its fields can
    change (a hashable field holds no array or list)."""
    if not type(value).__dataclass_params__.frozen:
        return False
    try:
        hash(value)
    except TypeError:
        return False
    return True


def molecule_key(frame, passes, context: bool = False) -> tuple:
    """The molecule layer's key of a frame: all it is drawn from, the probe excepted; with
    `context`, of the part the probe plane does not cut (the trace, the background)."""
    return (
        state_key(frame.scene, skip=("probe",)),
        state_key(frame.camera),
        tuple(frame.size),
        state_key(frame.view),
        state_key(frame.proj),
        state_key(frame.context_planes if context else frame.planes),
        state_key(frame.cube),
        state_key(frame.light_direction),
        frame.buffers.color_version,
        tuple((type(p).__name__, state_key(p.state())) for p in passes),
    )


@dataclass
class FramePlan:
    """What one frame redraws (see the module's docstring)."""

    kind: FrameKind = FrameKind.WHOLE
    size: tuple[int, int] = (1, 1)
    # KEPT and ATOMS_REDRAWN frames: the region of each footprint name.
    regions: dict[str, Rect | None] = field(default_factory=dict)
    # ATOMS_REDRAWN frames: the rectangle the atoms are drawn anew in (the cube's).
    redraw: Rect | None = None
    # What passes find once per molecule layer (its rectangles).
    layer_memo: dict = field(default_factory=dict)
    layer_version: int = 0  # counts the molecule layers drawn: a kept layer keeps its number

    @property
    def layered(self) -> bool:
        """Whether the frame is drawn in two layers, the molecule's kept for the next frames
        (the layered passes run)."""
        return self.kind != FrameKind.WHOLE

    @property
    def molecule_kept(self) -> bool:
        """Whether the molecule layer is the last frame's (its passes do not run)."""
        return self.kind == FrameKind.KEPT

    @property
    def context_kept(self) -> bool:
        """Whether the trace and the background beyond the cube are the last frame's (only the
        atoms are drawn anew, within `redraw`)."""
        return self.kind == FrameKind.ATOMS_REDRAWN

    def region(self, name: str) -> Rect | None:
        """The pixels to redo for footprint `name`: everything on a frame that draws the
        molecule layer anew."""
        if self.kind in (FrameKind.DRAWN, FrameKind.WHOLE):
            return full_rect(self.size)
        return union_rect(self.regions.get(name), self.redraw)


class FramePlanner:
    """The renderer's frames across time: the kept layer's key, the stash of what lies
    under the probe, and the footprints of the last frame."""

    def __init__(self, ctx, programs):
        self.ctx = ctx
        self.programs = programs
        self.stash: GBufferStash | None = None
        self.key: tuple | None = None  # the kept layer's key (None: none kept)
        self.context_key: tuple | None = None  # its context's (molecule_key's `context`)
        self.last_key: tuple | None = None  # the last frame's key, layer kept or not
        self.last_kind = FrameKind.WHOLE
        # What the stash holds: the probe's rectangle of the last frame.
        self.stashed: Rect | None = None
        self.footprints: dict[str, object] = {}  # the last frame's, by name
        self.layer_memo: dict = {}
        self.layer_version = 0
        self.counts = dict.fromkeys(FrameKind, 0)

    def plan(self, frame, passes) -> FramePlan:
        """This frame's plan; on a KEPT or ATOMS_REDRAWN frame the G-buffer gets back what the
        probe covered."""
        key = molecule_key(frame, passes)
        context_key = molecule_key(frame, passes, context=True) if frame.cube is not None else None
        kept_last = self.last_kind in (FrameKind.KEPT, FrameKind.ATOMS_REDRAWN)
        if key == self.key:
            kind = FrameKind.KEPT
        elif self.key is not None and context_key is not None and context_key == self.context_key:
            kind = FrameKind.ATOMS_REDRAWN
        elif not kept_last and self.last_key is not None and key != self.last_key:
            kind = FrameKind.WHOLE
        else:
            kind = FrameKind.DRAWN
        self.last_key, self.last_kind = key, kind
        self.key = None if kind == FrameKind.WHOLE else key
        self.context_key = None if kind == FrameKind.WHOLE else context_key
        self.counts[kind] += 1
        puts_back = kind in (FrameKind.KEPT, FrameKind.ATOMS_REDRAWN)
        if puts_back and self.stashed is not None:
            self.stash.restore(frame.targets, self.stashed)
        self.stashed = None
        if kind != FrameKind.KEPT:
            self.layer_memo = {}
            self.layer_version += 1
        plan = FramePlan(
            kind, tuple(frame.size), layer_memo=self.layer_memo, layer_version=self.layer_version
        )
        # The cube's pixels: its atoms' as they were and will be
        if kind == FrameKind.ATOMS_REDRAWN:
            plan.redraw = points_rect(frame.cube.corners(), frame.viewproj, frame.size, 2)
        frame.plan = plan
        now: dict[str, object] = {}
        if plan.layered:
            for p in passes:
                if p.enabled(frame):
                    for name, rect in p.footprint(frame).items():
                        now[name] = (
                            EVERYWHERE
                            if EVERYWHERE in (rect, now.get(name))
                            else union_rect(now.get(name), rect)
                        )
        if puts_back:
            plan.regions = {
                name: _region(self.footprints.get(name), now.get(name), plan.size)
                for name in set(now) | set(self.footprints)
            }
        self.footprints = now
        return plan

    def layer_counts(self) -> dict[str, int]:
        """Frames so far that kept the molecule layer, and that drew it (kept or not)."""
        kept = self.counts[FrameKind.KEPT]
        return {"kept": kept, "drawn": sum(self.counts.values()) - kept}

    def stash_under_probe(self, frame) -> None:
        """Keep the molecule layer's pixels the probe is about to cover (the layer is
        complete in the G-buffer, the probe not drawn yet)."""
        rect = frame.probe_rect()
        if self.stash is None or self.stash.size != tuple(frame.size):
            if self.stash is not None:
                self.stash.release()
            self.stash = GBufferStash(self.ctx, self.programs, frame.size)
        self.stash.save(frame.targets, rect)
        self.stashed = rect

    def release(self) -> None:
        if self.stash is not None:
            self.stash.release()
            self.stash = None


def _region(last, now, size) -> Rect | None:
    if EVERYWHERE in (last, now):
        return full_rect(size)
    return union_rect(last, now)
