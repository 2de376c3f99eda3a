"""The Falcon's wire formats: the Novint firmware's 16-byte frames and the loader's bytes.

From libnifalcon (commit f7c727a): FalconFirmwareNovintSDK.cpp (formatInput, formatOutput),
FalconFirmware.h (LED and homing flags), FalconCommLibUSB.cpp (setFirmwareMode),
FalconFirmware.cpp (loadFirmware).

A frame is '<', three signed 16-bit values as four nibbles each (least significant
first), two flag bytes, '>'; every byte between the brackets is its value + 0x41.
- To the Falcon: motor commands; byte 13 = LEDs | homing-mode bit 0x01; byte 14 = 0.
- From the Falcon: encoder counts; byte 13 − 0x41 = homed axes in bits 4-6 (axis 1 =
  0x10), buttons in bits 0-3. With homed axes byte 13 goes past 'P' (up to 0xC0), so it
  is not a nibble byte; byte 14 is undocumented and ignored, as libnifalcon does.
"""

from __future__ import annotations

from dataclasses import dataclass

FRAME_SIZE = 16
FRAME_START, FRAME_END = ord("<"), ord(">")
BYTE_OFFSET = 0x41  # 'A'

HOMING_MODE = 0x01
LED_GREEN, LED_RED = 0x2, 0x8  # (blue is 0x4)
HOMED_SHIFT = 4
ALL_HOMED = 0b111
STATUS_MAX = 0x7F  # three homed bits above four button bits

# Loader (firmware mode). libnifalcon's probe is answered by 00 0A 44 2C 0D on macOS and
# by its last four bytes on Linux; it tries up to 100 times, then sends 'A' and expects
# 'A' back; the image goes in chunks of 62 bytes, each echoed.
LOADER_PROBE = b"\x0a\x43\x0d"
LOADER_REPLIES = (b"\x0a\x44\x2c\x0d", b"\x00\x0a\x44\x2c\x0d")  # Linux, macOS
LOADER_PROBE_TRIES = 100
LOADER_HANDSHAKE = b"A"
UPLOAD_CHUNK = 62  # a 64-byte USB packet less the FTDI's two status bytes


class FrameError(ValueError):
    """Bytes that are not a valid Falcon frame."""


@dataclass(frozen=True)
class FalconReply:
    encoders: tuple[int, int, int]
    homed: int  # bit i: axis i has passed its index mark (bit 0 = top leg)
    buttons: int  # bit 0 far right, 1 centre forward, 2 centre circle, 3 far left


def _nibbles(values) -> list[int]:
    out = []
    for v in values:
        u = int(v) & 0xFFFF
        out += [(u >> (4 * k)) & 0xF for k in range(4)]
    return out


def encode_command(motor, leds: int, homing: bool) -> bytes:
    """Three signed motor commands, LED bits and the homing-mode bit as one frame."""
    body = _nibbles(motor) + [(leds & 0xE) | (HOMING_MODE if homing else 0), 0]
    return bytes([FRAME_START, *(b + BYTE_OFFSET for b in body), FRAME_END])


def decode_reply(frame: bytes) -> FalconReply:
    """One 16-byte frame from the Falcon; FrameError if it is not one."""
    if len(frame) != FRAME_SIZE:
        raise FrameError(f"frame of {len(frame)} bytes, expected {FRAME_SIZE}")
    if frame[0] != FRAME_START or frame[15] != FRAME_END:
        raise FrameError("frame not delimited by '<' ... '>'")
    nibbles = [b - BYTE_OFFSET for b in frame[1:13]]
    if any(n < 0 or n > 15 for n in nibbles):
        raise FrameError("encoder byte outside 'A'..'P'")
    status = frame[13] - BYTE_OFFSET
    if status < 0 or status > STATUS_MAX:
        raise FrameError("status byte out of range")
    encoders = []
    for i in range(3):
        u = sum(nibbles[4 * i + k] << (4 * k) for k in range(4))
        encoders.append(u - 0x10000 if u & 0x8000 else u)
    return FalconReply(tuple(encoders), (status >> HOMED_SHIFT) & ALL_HOMED, status & 0xF)


class FrameReader:
    """Frames out of a byte stream; each run of bytes it has to drop counts as one rejection."""

    def __init__(self):
        self.buffer = b""
        self.rejected = 0

    def clear(self) -> None:
        self.buffer = b""

    def feed(self, data: bytes) -> None:
        self.buffer += data

    def next_reply(self) -> FalconReply | None:
        while True:
            start = self.buffer.find(bytes([FRAME_START]))
            if start < 0:
                if self.buffer:
                    self.rejected += 1
                    self.buffer = b""
                return None
            if start > 0:
                self.rejected += 1
                self.buffer = self.buffer[start:]
            if len(self.buffer) < FRAME_SIZE:
                return None
            try:
                reply = decode_reply(self.buffer[:FRAME_SIZE])
            except FrameError:
                self.rejected += 1
                nxt = self.buffer.find(bytes([FRAME_START]), 1)
                self.buffer = self.buffer[nxt:] if nxt > 0 else b""
                continue
            self.buffer = self.buffer[FRAME_SIZE:]
            return reply
