"""What a daemon starts from: its structure, its (unopened) device, its checked settings and the
tick pipeline, from the command line's DaemonConfig (a replayed device brings the recording's
structure, settings and rate)."""

from __future__ import annotations

from dataclasses import dataclass

from sasprobe.daemon.config import DaemonConfig
from sasprobe.daemon.haptics import HapticPipeline, SafetyGuard, build_engine, validate_settings
from sasprobe.devices.base import DeviceLimits, HapticDevice
from sasprobe.molecule import Structure


@dataclass
class SessionStart:
    structure: Structure
    keep_water: bool
    device: HapticDevice
    rate_hz: float | None  # None: free-running (a replay at --speed max)
    limits: DeviceLimits
    settings: dict  # validate_settings' form
    pipeline: HapticPipeline


def open_session(config: DaemonConfig) -> SessionStart:
    from sasprobe.devices.registry import open_device
    from sasprobe.molecule import load_structure_or_default, parse_structure

    structure = load_structure_or_default(config.molecule, keep_water=config.keep_water)
    keep_water = config.keep_water
    device = open_device(config.device, structure=structure, rate_hz=config.rate_hz,
                         seed=config.seed, speed=config.speed, faults=config.faults,
                         button_presses=config.button_presses,
                         probe_radius_A=config.settings.get("probe_radius_A"),
                         cube_half_A=config.settings.get("cube_half_A"))
    settings = dict(config.settings)
    rate_hz = config.rate_hz
    session = device.recorded_session()
    if session is not None:  # a replay: the recording's structure (unless given), settings and rate
        if config.molecule is None:
            structure = parse_structure(session.structure_bytes, name=session.structure_name,
                                        source=f"{config.device} (recorded)", keep_water=session.keep_water)
            keep_water = session.keep_water
        settings = {**session.settings, **settings}
        rate_hz = None if config.speed is None else session.rate_hz * config.speed
    limits = device.info.limits
    settings = validate_settings(settings, limits)
    pipeline = HapticPipeline(build_engine(structure, limits, settings), SafetyGuard(limits))
    return SessionStart(structure, keep_water, device, rate_hz, limits, settings, pipeline)
