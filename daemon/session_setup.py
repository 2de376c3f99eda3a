"""What a daemon's session is set up from: the structure, the (unopened) device, the loop
rate and the settings, from the command line's DaemonConfig or, for a replay, from the
recording. The limits, the settings checked against them and the pipeline wait until the
device is open, since some arms tell their workspace and limits only then (an OpenHaptics
arm after hdInitDevice, a WoodenHaptics board in its first reply); the loop rate cannot
wait: it is the command line's, or the rate the device declares before it opens
(`DeviceLimits.nominal_rate_hz`), and never above the fastest it declares
(`DeviceLimits.max_rate_hz`)."""

from __future__ import annotations

from dataclasses import dataclass

from sasprobe.daemon.config import DaemonConfig
from sasprobe.daemon.haptics import HapticPipeline, SafetyGuard, build_engine, validate_settings
from sasprobe.devices.base import DeviceLimits, HapticDevice
from sasprobe.molecule import Structure

from sasprobe.common.errors import UserError


@dataclass
class SessionSetup:
    structure: Structure
    keep_water: bool
    device: HapticDevice
    rate_hz: float | None  # None: free-running (a replay at --speed max)
    settings: dict  # as given: checked against the opened device's limits by build_pipeline()

    def build_pipeline(self) -> tuple[DeviceLimits, dict, HapticPipeline]:
        """The opened device's limits, the settings checked against them (validate_settings'
        form) and the tick pipeline built for them; call it once the device is open."""
        limits = self.device.info.limits
        settings = validate_settings(self.settings, limits, self.rate_hz)
        return (
            limits,
            settings,
            HapticPipeline(build_engine(self.structure, limits, settings), SafetyGuard(limits)),
        )


def prepare_session(config: DaemonConfig) -> SessionSetup:
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
    limits = device.info.limits
    rate_hz = config.rate_hz or limits.nominal_rate_hz
    session = device.recorded_session()
    if session is None and rate_hz > limits.max_rate_hz:
        raise UserError(
            f"--rate {rate_hz:g}: --device {config.device} runs at most "
            f"{limits.max_rate_hz:g} Hz (by default {limits.nominal_rate_hz:g} Hz)"
        )
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
    return SessionSetup(structure, keep_water, device, rate_hz, settings)
