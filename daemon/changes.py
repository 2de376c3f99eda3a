"""The changes the control thread (daemon/requests.py) and the device's buttons ask of the
loop: each is prepared off the loop, handed over with `submit` and applied at the start of
the next tick, on the loop thread, where it is recorded and the scene rebuilt. A mixin of
`Daemon` (daemon/service.py), whose state it changes."""

from __future__ import annotations

import collections
import time
from concurrent.futures import Future, TimeoutError as FutureTimeout

from sasprobe.daemon.marks import mark_button
from sasprobe.daemon.deferred_release import DeferredRelease
from sasprobe.daemon.scene_message import rotation_rows
from sasprobe.common.errors import UserError

SUBMIT_TIMEOUT_S = 5.0


class LoopChanges:
    _pending: collections.deque  # (closure, Future) for the loop, made by Daemon
    deferred_release: DeferredRelease  # what a change replaced, made by Daemon

    def submit(self, fn):
        """Run fn(seq) on the loop thread at the start of the next tick and return its result."""
        future: Future = Future()
        self._pending.append((fn, future))
        try:
            return future.result(timeout=SUBMIT_TIMEOUT_S)
        except FutureTimeout:
            raise UserError("the daemon loop did not take the change in time (is it shutting down?)") from None
        finally:
            self.deferred_release.release()  # what the change replaced, freed here rather than on the loop

    def _apply_pending(self, seq: int) -> None:
        while self._pending:
            fn, future = self._pending.popleft()
            try:
                future.set_result(fn(seq))
            except Exception as exc:
                future.set_exception(exc)

    def swap_structure(self, structure, keep_water: bool, engine, seq: int) -> int:
        """On the loop thread: a new structure and its engine (built off the loop)."""
        self.deferred_release.add(self.structure, self.pipeline.engine)
        self.structure = structure
        self.structure_keep_water = keep_water
        self.pipeline.replace_engine(engine)
        if self.recorder is not None:
            self.recorder.offer_structure(time.monotonic_ns(), structure.name, structure.source_bytes)
        self.record_control(seq, "load", {"sha256": structure.sha256, "name": structure.name, "keep_water": keep_water})
        self.rebuild_scene()
        return seq

    def apply_settings(self, haptic: dict, scene_only: dict, settings: dict, lights: dict | None, engine,
                       seq: int) -> int:
        """On the loop thread: a checked `set` (a new engine when one had to be built)."""
        if engine is not None:
            self.deferred_release.add(self.pipeline.engine)
            self.pipeline.replace_engine(engine)
        elif haptic:
            self.pipeline.engine.update(**haptic)
        self.settings = settings
        if "clip_planes" in scene_only:
            self.clip_planes = scene_only["clip_planes"]
        if lights is not None:
            self.lights = lights
        if "nav_cube_enabled" in scene_only:
            self.nav_cube_enabled = scene_only["nav_cube_enabled"]
        if "color_scheme" in scene_only:
            self.color_scheme = scene_only["color_scheme"]
        self.record_control(seq, "set", {**haptic, **scene_only})
        self.rebuild_scene()
        return seq

    def workspace_action(self, action: str, args: dict, seq: int) -> None:
        """On the loop thread: a clutch change or a pressed action (device button, window key), recorded."""
        if action == "clutch":
            self.pipeline.set_clutch(args["held"])
        elif action == "recentre":
            self.pipeline.recentre()
        elif action == "mark":
            mark_button(self, seq)  # records its own `mark`
            return
        else:
            return
        self.record_control(seq, action, args)

    def turn_view(self, rotation: tuple[float, ...], seq: int) -> int:
        """On the loop thread: the workspace view turned (control `view`); the mapping turns with it."""
        self.pipeline.set_view(rotation)
        self.record_control(seq, "view", {"rotation": rotation_rows(rotation)})
        self.rebuild_scene()
        return seq
