"""The haptic engine as the daemon drives it, with settings as plain JSON-able dicts.

The daemon, the control server and `replay --verify` all go through one backend, so a
settings change is applied the same way live and in a replay. Changes to REBUILD_FIELDS
build a new engine away from the loop (building the grid of a large structure takes
longer than a tick) and swap it in; the others are applied in the loop with update().
"""

from __future__ import annotations

from sasprobe.devices.base import DeviceLimits

HAPTIC_FIELDS = ("probe_radius_A", "method", "stiffness_n_per_mm", "damping_n_s_per_m", "cube_half_A")
REBUILD_FIELDS = frozenset({"probe_radius_A"})  # a new grid: built off the loop


def split_changes(changes: dict) -> tuple[dict, dict]:
    """(haptic engine fields, scene-only fields) of a `set`."""
    haptic = {k: v for k, v in changes.items() if k in HAPTIC_FIELDS}
    return haptic, {k: v for k, v in changes.items() if k not in HAPTIC_FIELDS}


def needs_rebuild(haptic_changes: dict) -> bool:
    return bool(REBUILD_FIELDS & set(haptic_changes))


def apply_recorded_event(event: dict, pipeline, backend, structure, settings: dict, limits: DeviceLimits,
                         structure_for_sha) -> tuple[object, dict]:
    """Apply a recorded `set`/`load`/`reconnect` as the live daemon did; return (structure, settings).

    Live, the control thread builds new engines and the loop swaps them in; a replay
    (live or `--verify`) does the same steps in line, so the forces come out identical.
    """
    cmd, args = event.get("cmd"), event.get("args", {})
    if cmd == "set":
        haptic, _ = split_changes(args)
        if needs_rebuild(haptic):
            settings = backend.validate({**settings, **haptic}, limits)
            pipeline.replace_engine(backend.build(structure, limits, settings))
        elif haptic:
            pipeline.engine.update(**haptic)
            settings = backend.validate({**settings, **haptic}, limits)
    elif cmd == "load":
        structure = structure_for_sha(args["sha256"], args.get("keep_water", False))
        pipeline.replace_engine(backend.build(structure, limits, settings))
    elif cmd == "reconnect":
        pipeline.reconnected()
    return structure, settings


class HapticBackend:
    """Builds and validates sasprobe.daemon.haptics engines (the HapticRenderer)."""

    def _module(self):
        from sasprobe.daemon import haptics

        return haptics

    def validate(self, settings: dict, limits: DeviceLimits) -> dict:
        """Complete and check settings; ValueError with one clear line when a value is bad."""
        haptics = self._module()
        try:
            checked = haptics.HapticSettings(**settings).validated(limits)
        except TypeError as exc:  # an unknown field name
            raise ValueError(str(exc)) from None
        return {name: getattr(checked, name) for name in HAPTIC_FIELDS}

    def build(self, structure, limits: DeviceLimits, settings: dict):
        haptics = self._module()
        return haptics.HapticRenderer(structure, limits, haptics.HapticSettings(**settings).validated(limits))
