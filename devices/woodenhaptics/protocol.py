"""The WoodenHaptics/Polhem Teensy line protocol (ASCII over USB serial, one reply per command).

From the firmware, forsslund/woodenhaptics at 6b9ad8a,
`firmware/woody_teensy_mini/woody_teensy_mini.ino`, and the host library's copy of the
message structs, forsslund/hfabapi at cf00e97 `hfab_protocol.h`:

- host → board `[ma0,ma1,ma2]` and a newline: three motor currents in mA
  (`pc_to_device_message`). The firmware reads up to ']' and then drains what is
  already waiting: anything but '\\n', '\\r' or NUL there means a second command merged
  into this one, and the command is refused (error 8);
- board → host `[model,enc0,enc1,enc2,enc3,enc4,enc5,error]` and a newline
  (`device_to_pc_message`): the model code, three motor encoders and three gimbal
  encoders (raw counts) and the error field below;
- a current beyond ±6000 mA (`escon_max_milliamps`) is replaced by 0, not clipped;
- a refused command is answered with the last counts (`return_last_values`), so its
  reply says nothing about the present pose;
- 100 ms without an accepted command (`wdTimer`) switches the amplifiers off; the
  next accepted command switches them on again.
"""

from __future__ import annotations

from dataclasses import dataclass

from sasprobe.devices.serial_arm import ArmReply, BadFrame

MAX_CURRENT_MA = 6000  # escon_max_milliamps
WATCHDOG_S = 0.100  # wdTimer.begin(wdCallback, 100000)
FIELDS = 8

# The reply's error field (await_message() and the gimbal reads of loop()).
ERROR_NAMES = {
    1: "gimbal sensor 0 unread",
    2: "gimbal sensor 1 unread",
    4: "gimbal sensor 2 unread",
    8: "trailing characters (merged commands)",
    128: "buffer full",
    256: "no '[' before ']'",
    512: "wrong number of currents",
    1024: "parse error",
}
GIMBAL_ERRORS = 1 | 2 | 4
REFUSED = 8 | 128 | 256 | 512 | 1024  # the command was not taken

ZERO_COMMAND = b"[0,0,0]\n"
MAX_LINE = 127  # the firmware's buffer; a longer reply cannot be one of its lines


@dataclass(frozen=True)
class WoodyReply(ArmReply):
    model: int
    counts: tuple[int, int, int, int, int, int]
    error: int

    @property
    def refused(self) -> bool:
        return bool(self.error & REFUSED)


def encode_command(currents_ma) -> bytes:
    return ("[" + ",".join(str(int(round(c))) for c in currents_ma) + "]\n").encode("ascii")


def parse_reply(line: bytes) -> WoodyReply:
    """One reply line (without its newline); BadFrame when it is not one."""
    try:
        text = line.decode("ascii").strip()
    except UnicodeDecodeError:
        raise BadFrame(f"bytes that are not a WoodenHaptics reply: {line[:40]!r}") from None
    fields = text[1:-1].split(",") if text.startswith("[") and text.endswith("]") else []
    try:
        values = [int(f) for f in fields]
    except ValueError:
        values = []
    if len(values) != FIELDS:
        raise BadFrame(f"a line that is not a WoodenHaptics reply: {text[:40]!r}")
    return WoodyReply(values[0], tuple(values[1:7]), values[7])


def split_reply(inbox: bytes) -> tuple[WoodyReply | None, bytes]:
    """The first complete reply line of `inbox` and the rest; (None, inbox) while incomplete."""
    end = inbox.find(b"\n")
    if end < 0:
        if len(inbox) > MAX_LINE:
            raise BadFrame(f"{len(inbox)} bytes without a newline")
        return None, inbox
    return parse_reply(inbox[:end]), inbox[end + 1 :]


def describe_errors(bits: int) -> str:
    return ", ".join(name for bit, name in ERROR_NAMES.items() if bits & bit) or "none"
