"""The Haply M0/M3 board protocol (binary, USB serial): reset, setup, write → angles.

From the board firmware, HaplyHaptics/Haply-Arduino-Firmware-Versions at 6f75c27
(`Haply_M0_Firmware_V0_3/*` and `Haply_M3_Firmware_V1_5/*`: `loop()`,
`command_instructions()`, `reset_haply()`, `setup_device()`, `write_states()`,
`read_states()`, `create_torque()`), and the host side of Haply's libraries
(Haply-API-cpp v1.0.0 `Board::transmit()`, `Device::device_set_parameters()`,
`Device::device_write_torques()`; `HaplyHAPI.py` the same):

- every message starts with a command byte: 0 reset, 1 setup, 2 write; any other
  byte is skipped. The next byte is the device ID (the reset's is 0);
- setup: motor port mask (bit p−1 for port p), one direction byte per active motor,
  encoder port mask, one direction byte per active encoder, the number of analog
  sensors (0 here) and their pins, the number of PWM pins (0) and their pins, then
  per active encoder two float32 (start angle in degrees, resolution in counts per
  turn), all in port order. The board sends nothing back;
- write: the device ID, one byte per PWM pin (none here), one float32 torque (N·m) per
  active motor in port order. The board answers with the device ID and one float32
  per analog sensor, then one float32 angle (degrees) per active encoder, in port
  order — just the ID when it has not been set up;
- floats are IEEE 754, least significant byte first;
- the board clamps each torque to MAX_TORQUE (0.123 N·m) and has no watchdog: the
  last torque stays on until the next write.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from sasprobe.devices.serial_arm import ArmReply, BadFrame

RESET, SETUP, WRITE = 0, 1, 2
MAX_TORQUE_NM = 0.123  # MAX_TORQUE in both firmwares
DEFAULT_DEVICE_ID = 5  # Haply's examples use 5 (HaplyHAPI README, Haply-API-cpp example/main.cpp)


@dataclass(frozen=True)
class Angles(ArmReply):
    degrees: tuple[float, ...]  # per active encoder, in port order


def port_mask(ports) -> int:
    mask = 0
    for port in ports:
        mask |= 1 << (port - 1)
    return mask


def encode_reset() -> bytes:
    return bytes([RESET, 0])


def encode_setup(device_id: int, ports) -> bytes:
    """`ports`: PortSetup-like objects (port, motor_direction, encoder_direction, start_angle_deg,
    counts_per_turn), one per motor with its encoder."""
    ports = sorted(ports, key=lambda p: p.port)
    mask = port_mask(p.port for p in ports)
    head = bytes(
        [
            SETUP,
            device_id,
            mask,
            *(p.motor_direction for p in ports),
            mask,
            *(p.encoder_direction for p in ports),
            0,
            0,
        ]
    )
    floats = [v for p in ports for v in (p.start_angle_deg, p.counts_per_turn)]
    return head + struct.pack(f"<{len(floats)}f", *floats)


def encode_write(device_id: int, torques_nm) -> bytes:
    return bytes([WRITE, device_id]) + struct.pack(f"<{len(torques_nm)}f", *torques_nm)


def reply_size(encoders: int) -> int:
    return 1 + 4 * encoders


def decode_angles(frame: bytes, device_id: int, encoders: int) -> Angles:
    """One reply frame of exactly `reply_size(encoders)` bytes; BadFrame when it is not ours."""
    if len(frame) != reply_size(encoders) or frame[0] != device_id:
        raise BadFrame(f"a frame that is not this board's reply: {frame[:16].hex(' ')}")
    degrees = struct.unpack(f"<{encoders}f", frame[1:])
    if not all(math.isfinite(a) for a in degrees):
        raise BadFrame(f"a reply with non-finite angles: {frame.hex(' ')}")
    return Angles(tuple(degrees))
