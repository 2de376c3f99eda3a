"""Device buttons and window keys as workspace actions: clutch (held), recentre and mark (pressed).

`ButtonMap` says which device button does what (`sasprobe daemon --button ACTION=N`,
repeatable, or `button = ["clutch=0", ...]` in the config file; defaults below: on a
PHANTOM Omni the stylus' front button is 0, the rear one 1) and turns the buttons
bitmask of each reading into the actions held and the actions pressed since the last
reading (edges). `WorkspaceInputs` adds the window's clutch key, which arrives over the
control socket: `clutch {"held": true}` holds it for KEY_CLUTCH_LEASE_S and the window
renews it while the key is down, so a renderer that dies with the key down cannot
leave the probe clutched. The loop asks it once per tick what changed.

The loop turns these into pipeline calls and records them as control records
(`clutch`, `recentre`), so a replay repeats the recorded effect rather than
re-interpreting buttons; a replayed device's buttons are therefore not mapped again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

ACTIONS = ("clutch", "recentre", "mark")
HELD_ACTIONS = frozenset({"clutch"})  # effective while the button is down; the others on the press
DEFAULT_BUTTONS = {"clutch": 0, "recentre": 1, "mark": 2}
MAX_BUTTON = 31  # the pose's buttons field is 32 bits
KEY_CLUTCH_LEASE_S = 1.0


def parse_button(text: str) -> tuple[str, int]:
    """'ACTION=N' -> (action, button index); ValueError (one line) otherwise."""
    action, sep, number = text.partition("=")
    action = action.strip().lower()
    if not sep or action not in ACTIONS:
        raise ValueError(f"'{text}': expected ACTION=N with ACTION one of {', '.join(ACTIONS)}")
    try:
        index = int(number)
    except ValueError:
        raise ValueError(f"'{text}': the button must be a number 0..{MAX_BUTTON}") from None
    if not 0 <= index <= MAX_BUTTON:
        raise ValueError(f"'{text}': the button must be 0..{MAX_BUTTON}")
    return action, index


@dataclass
class ButtonMap:
    """Action -> device button index, with edge detection over successive readings."""

    buttons: dict[str, int] = field(default_factory=lambda: dict(DEFAULT_BUTTONS))
    _previous: int = 0

    @classmethod
    def from_options(cls, options: list[str] | None) -> ButtonMap:
        """The defaults with `--button ACTION=N` options applied; ValueError on a bad one."""
        buttons = dict(DEFAULT_BUTTONS)
        for text in options or ():
            action, index = parse_button(text)
            buttons[action] = index
        return cls(buttons)

    def update(self, bits: int) -> tuple[set[str], set[str]]:
        """(actions whose button is down, actions whose button went down since the last call)."""
        bits = int(bits)
        rising = bits & ~self._previous
        self._previous = bits
        held = {a for a, i in self.buttons.items() if bits >> i & 1}
        pressed = {a for a, i in self.buttons.items() if rising >> i & 1}
        return held, pressed


class WorkspaceInputs:
    """What the loop should do about the clutch and the pressed actions, tick by tick."""

    def __init__(self, button_map: ButtonMap, map_device_buttons: bool = True) -> None:
        self.button_map = button_map
        self.map_device_buttons = map_device_buttons  # False for a replayed session
        self._button_clutch = False
        self._key_until_ns: int | None = None
        self.clutched = False  # what the pipeline was last told

    def key_clutch(self, held: bool, now_ns: int) -> None:
        """The window's clutch key (control `clutch`): held for a lease, or released."""
        self._key_until_ns = now_ns + int(KEY_CLUTCH_LEASE_S * 1e9) if held else None

    def tick(self, buttons: int | None, now_ns: int) -> list[tuple[str, dict]]:
        """The actions of this tick, in order: ("clutch", {"held": bool}) when the clutch
        changes, then each pressed action (`buttons` None: no reading this tick)."""
        actions: list[tuple[str, dict]] = []
        pressed: set[str] = set()
        if buttons is not None and self.map_device_buttons:
            held, pressed = self.button_map.update(buttons)
            self._button_clutch = "clutch" in held
        if self._key_until_ns is not None and now_ns > self._key_until_ns:
            self._key_until_ns = None  # the window stopped renewing: let go
        clutched = self._button_clutch or self._key_until_ns is not None
        if clutched != self.clutched:
            self.clutched = clutched
            actions.append(("clutch", {"held": clutched}))
        actions += [
            (action, {}) for action in ACTIONS if action in pressed and action not in HELD_ACTIONS
        ]
        return actions
