"""Uploading the Novint firmware into a freshly powered Falcon, as libnifalcon does on Linux.

FalconCommLibUSB::setFirmwareMode: purge; latency timer 16 ms; 9600 baud (divisor 0x4138),
8N1, no flow control; RTS low, DTR low, DTR high; then up to 100 times: send 0A 43 0D and
read one packet, until it holds 0A 44 2C 0D (Linux: four bytes) or 00 0A 44 2C 0D
(macOS); DTR low, divisor 0x15, send 'A', expect 'A'. FalconFirmware::loadFirmware: the
image in 62-byte chunks, each echoed back and compared; then normal mode.

Where we differ: one probe read waits at most 0.1 s, not 1 s (the FTDI answers every
16 ms with at least its status bytes, so this only bounds a link that sends nothing),
and an echo must arrive within 1 s instead of being awaited without end.
"""

from __future__ import annotations

import time

from sasprobe.devices.falcon import ftdi
from sasprobe.devices.falcon import protocol as P

PROBE_READ_S = 0.1
ECHO_WAIT_S = 1.0


class LoaderSilent(Exception):
    """The loader never answered its probe: retrying the upload will not help."""


class UploadFailed(Exception):
    """The loader answered but the handshake or an echo went wrong: worth another attempt."""


def enter_firmware_mode(link: ftdi.FtdiLink) -> int:
    """The loader handshake; returns how many probes it took."""
    link.purge()
    link.request(ftdi.SIO_SET_LATENCY_TIMER, ftdi.LATENCY_LOADER_MS)
    link.request(ftdi.SIO_SET_BAUD_RATE, ftdi.DIVISOR_9600)
    link.request(ftdi.SIO_SET_DATA, ftdi.DATA_8N1)
    link.request(ftdi.SIO_SET_FLOW_CTRL, 0)
    link.request(ftdi.SIO_MODEM_CTRL, ftdi.RTS_LOW)
    link.request(ftdi.SIO_MODEM_CTRL, ftdi.DTR_LOW)
    link.request(ftdi.SIO_MODEM_CTRL, ftdi.DTR_HIGH)
    probes = _probe(link)
    link.request(ftdi.SIO_MODEM_CTRL, ftdi.DTR_LOW)
    link.request(ftdi.SIO_SET_BAUD_RATE, ftdi.DIVISOR_LOADER)
    link.write_blocking(P.LOADER_HANDSHAKE)
    if link.read_packet(PROBE_READ_S) != P.LOADER_HANDSHAKE:
        raise UploadFailed("the loader did not echo its handshake")
    return probes


def _probe(link: ftdi.FtdiLink) -> int:
    """Probe the loader until it answers; the number of the probe it answered."""
    for probe in range(1, P.LOADER_PROBE_TRIES + 1):
        link.write_blocking(P.LOADER_PROBE)
        if link.read_packet(PROBE_READ_S) in P.LOADER_REPLIES:
            return probe
    raise LoaderSilent(f"the Falcon's loader did not answer {P.LOADER_PROBE_TRIES} probes")


def upload(link: ftdi.FtdiLink, image: bytes) -> None:
    """Send the image chunk by chunk, comparing each echo; then switch to normal mode."""
    for offset in range(0, len(image), P.UPLOAD_CHUNK):
        chunk = image[offset : offset + P.UPLOAD_CHUNK]
        link.write_blocking(chunk)
        echo, deadline = b"", time.monotonic() + ECHO_WAIT_S
        while len(echo) < len(chunk):
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise UploadFailed(
                    f"no echo of the chunk at byte {offset} ({len(echo)} of {len(chunk)} bytes)"
                )
            echo += link.read_packet(min(remaining, PROBE_READ_S))
        if echo != chunk:
            raise UploadFailed(f"the echo of the chunk at byte {offset} differs")
    link.normal_mode()
