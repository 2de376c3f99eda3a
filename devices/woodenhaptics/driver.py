"""The WoodenHaptics/Polhem arm as a HapticDevice: the Teensy line protocol, hfabapi's models.

The session is the shared serial-arm exchange (`serial_arm.py`): one command in
flight, fresh replies only, resynchronising after a refused or garbled reply. Opening
resends `[0,0,0]` every 100 ms until the board answers (hfabapi `wait_online()`), then
takes the model from the reply; an unknown model code is refused by name.

Calibration: the firmware counts from the pose where it powered up or where its
calibration button was last pressed, and nothing in the protocol says which; hfabapi
assumes the model's home pose (its home counts) and so do we: `calibrated` is always
True. Power the arm up, or press its button, in the home pose (docs/connect-your-arm.md).
"""

from __future__ import annotations

import logging

import numpy as np
from sasprobe.devices.base import DeviceFault, DeviceInfo, DeviceOpenError
from sasprobe.devices.kinematics import KinematicsError
from sasprobe.devices.serial_arm import SerialArm, timing_options
from sasprobe.devices.woodenhaptics import kinematics, protocol
from sasprobe.devices.woodenhaptics.models import (
    LIMITS_BEFORE_THE_MODEL_IS_KNOWN,
    WOODEN_MODELS,
    WoodenModel,
    known_models,
)

log = logging.getLogger("sasprobe.devices.woodenhaptics")


class WoodenHapticsDevice(SerialArm):
    scheme = "woodenhaptics"

    def __init__(self, port: str | None, **timing):
        super().__init__(port, **timing)
        self.model: WoodenModel | None = None
        self.counts = (0, 0, 0, 0, 0, 0)  # raw counts of the last reply taken
        self.angles = np.zeros(3)
        self.device_error_bits = 0
        self.gimbal_errors = 0
        self._position = np.zeros(3)
        self._orientation = np.array([1.0, 0.0, 0.0, 0.0])
        self._unreachable: str | None = None

    @property
    def _max_force_n(self) -> float:
        return (self.model.limits if self.model else LIMITS_BEFORE_THE_MODEL_IS_KNOWN).max_force_n

    @property
    def info(self) -> DeviceInfo:
        model = self.model
        return DeviceInfo(
            kind=self.scheme,
            model=model.name if model else "WoodenHaptics arm",
            limits=model.limits if model else LIMITS_BEFORE_THE_MODEL_IS_KNOWN,
            serial=self.port,
            details={
                "model_code": model.code if model else None,
                "hfab_configuration": model.configuration if model else None,
                "counts": list(self.counts),
                "device_error_bits": self.device_error_bits,
                "device_errors": protocol.describe_errors(self.device_error_bits),
                "rejected_frames": self.rejected_frames,
                "refused_commands": self.refused_commands,
                "stale_replies": self.stale_replies,
                "resyncs": self.resyncs,
                "replies": self.replies,
            },
        )

    # wire -----------------------------------------------------------------------------
    def _handshake(self, timeout_s: float) -> None:
        self.model = None
        self._probe(
            timeout_s,
            lambda junk: (
                f"{self.port} answered, but not in the WoodenHaptics line format "
                f"([model,enc0..enc5,error]): got {junk[-40:]!r}"
            ),
        )

    def _zero_command(self) -> bytes:
        return protocol.ZERO_COMMAND

    def _command(self) -> bytes:
        if self.model is None or self._unreachable:
            return protocol.ZERO_COMMAND
        return protocol.encode_command(
            kinematics.motor_currents_ma(self.model, self.angles, self.force)
        )

    def _split(self, inbox: bytes):
        reply, rest = protocol.split_reply(inbox)
        if reply is not None and self.model is not None and reply.model != self.model.code:
            raise protocol.BadFrame(
                f"a reply from model {reply.model} on a model {self.model.code} arm"
            )
        return reply, rest

    def _take(self, reply: protocol.WoodyReply) -> None:
        if self.model is None:
            self.model = self._adopt(reply.model)
        self._note_errors(reply.error)
        self.counts = reply.counts
        self.angles = kinematics.body_angles(self.model, reply.counts)
        try:
            self._position, lam = kinematics.tip_position_mm(self.model, self.angles)
        except KinematicsError as exc:
            self._unreachable = str(exc)  # no force from a pose that cannot be
            return
        self._unreachable = None
        self._orientation = kinematics.orientation(self.model, self.angles, lam, reply.counts)

    def _state(self, t_ns: int):
        if self._unreachable:
            raise DeviceFault(self._unreachable)
        return self._position.copy(), self._orientation.copy(), 0  # hfabapi reads no stylus switch

    def _adopt(self, code: int) -> WoodenModel:
        model = WOODEN_MODELS.get(code)
        if model is None:
            raise DeviceOpenError(
                f"the arm on {self.port} reports model code {code}, which sasprobe does not "
                f"know (known: {known_models()})"
            )
        log.info("%s: %s (model %d, hfabapi %s)", self.port, model.name, code, model.configuration)
        return model

    def _note_errors(self, bits: int) -> None:
        if bits & protocol.GIMBAL_ERRORS:
            self.gimbal_errors += 1
        if bits != self.device_error_bits:
            if bits:
                log.warning("%s reports: %s", self.port, protocol.describe_errors(bits))
            self.device_error_bits = bits


def create(argument: str | None = None, **options) -> WoodenHapticsDevice:
    """`woodenhaptics:PORT`. Options: rate_hz, reply_timeout_s, stale_after_s,
    handshake_timeout_s."""
    return WoodenHapticsDevice(argument, **timing_options(options))
