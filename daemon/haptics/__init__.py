"""Haptic rendering of the SAS, one control tick at a time: no clock, no socket, no thread.

engine (workspace mapping -> contact -> force law) -> safety guard -> pipeline (flags,
pose fields). Everything here is a pure function of its inputs and its own state, so a
recording's inputs replay to the same forces bit for bit.
"""

from sasprobe.daemon.haptics.engine import HapticEngine, HapticOutput, build_engine
from sasprobe.daemon.haptics.pipeline import HapticPipeline, TickResult
from sasprobe.daemon.haptics.safety import SafetyGuard
from sasprobe.daemon.haptics.settings import HapticSettings, validate_settings

__all__ = [
    "HapticEngine",
    "HapticOutput",
    "HapticPipeline",
    "HapticSettings",
    "SafetyGuard",
    "TickResult",
    "build_engine",
    "validate_settings",
]
