"""What a daemon starts from: its structure, its (unopened) device and its settings, from the
command line's DaemonConfig (a replayed device brings the recording's structure, settings and
rate); once the device is open, its limits, the settings checked against them and the tick
pipeline. Some arms tell their workspace and limits only when opened (an OpenHaptics arm
answers HD_USABLE_WORKSPACE_DIMENSIONS after hdInitDevice; a WoodenHaptics board names its
model in its first reply), so nothing is built from an unopened device's, but for the loop
rate: unless the command line gives one, the rate the device declares before it opens
(`DeviceLimits.nominal_rate_hz`: 1000 Hz for every arm but those an Inverse Service serves)."""

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
    settings: dict  # as given: checked against the opened device's limits by `pipeline()`

    def pipeline(self) -> tuple[DeviceLimits, dict, HapticPipeline]:
        """The opened device's limits, the settings checked against them (validate_settings'
        form) and the tick pipeline built for them; call it once the device is open."""
        limits = self.device.info.limits
        settings = validate_settings(self.settings, limits)
        return (
            limits,
            settings,
            HapticPipeline(build_engine(self.structure, limits, settings), SafetyGuard(limits)),
        )


def open_session(config: DaemonConfig) -> SessionStart:
    from sasprobe.devices.registry import open_device
    from sasprobe.molecule import load_structure_or_default, parse_structure

    structure = load_structure_or_default(config.molecule, keep_water=config.keep_water)
    keep_water = config.keep_water
    device = open_device(
        config.device,
        structure=structure,
        rate_hz=config.rate_hz,
        seed=config.seed,
        speed=config.speed,
        faults=config.faults,
        button_presses=config.button_presses,
        probe_radius_A=config.settings.get("probe_radius_A"),
        cube_half_A=config.settings.get("cube_half_A"),
    )
    settings = dict(config.settings)
    rate_hz = config.rate_hz or device.info.limits.nominal_rate_hz
    session = device.recorded_session()
    if session is not None:  # a replay: the recording's structure (unless given), settings and rate
        if config.molecule is None:
            structure = parse_structure(
                session.structure_bytes,
                name=session.structure_name,
                source=f"{config.device} (recorded)",
                keep_water=session.keep_water,
            )
            keep_water = session.keep_water
        settings = {**session.settings, **settings}
        rate_hz = None if config.speed is None else session.rate_hz * config.speed
    return SessionStart(structure, keep_water, device, rate_hz, settings)
