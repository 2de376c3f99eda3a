"""Which 3Dconnexion products are 6-DoF devices, and how each one's axes and buttons map.

The one home of these facts, all from spacenavd (FreeSpacenav/spacenavd, commit
bac572ae1e2dff288a072896880f0a6431d046e4): `usbdb` in src/dev.c is the device list with
its per-model flags and button remaps, `devid_blacklist` the 3Dconnexion products that
are not 6-DoF devices, `match_usbdev` the rule for the universal receiver, and
`open_dev_usb` in src/dev_usb_linux.c the guess of which device sits behind it.

- `newer_axes`: spacenavd's DF_SWAPYZ | DF_INVYZ (always set together). Every listed
  model has them except the SpaceMouse Plus XT, the SpaceMouse Classic and the NuLOOQ,
  which already report the axis order of the old serial devices.
- `buttons`: spacenavd's bnhack_smpro / bnhack_sment, which number the buttons of the
  SpaceMouse Pro and Enterprise (their raw numbers are sparse). spacenavd reads evdev key
  codes; the Linux HID layer gives button usage n of a multi-axis controller the code
  BTN_MISC + n - 1 (drivers/hid/hid-input.c, hidinput_configure_usage), so bit i of
  HID report 3 is code 0x100 + i. The tables below keep spacenavd's codes. Buttons a
  remap does not name are ignored, as spacenavd ignores them; models without a remap
  number their buttons by report bit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

BTN_MISC = 0x100  # evdev code of HID button usage 1 on a multi-axis controller


def _by_report_bit(codes: dict[int, int]) -> dict[int, int]:
    """spacenavd's {evdev code: button} → {HID report-3 bit: button}."""
    return {code - BTN_MISC: button for code, button in codes.items()}


# bnhack_smpro: SpaceMouse Pro and Pro Wireless (15 buttons)
SPACEMOUSE_PRO_BUTTONS = _by_report_bit(
    {
        256: 4,
        257: 5,
        258: 6,
        260: 7,
        261: 8,
        264: 9,  # menu, fit, [T], [R], [F], [ ]
        268: 0,
        269: 1,
        270: 2,
        271: 3,  # 1..4
        278: 11,
        279: 12,
        280: 13,
        281: 14,
        282: 10,  # esc, alt, shift, ctrl, lock
    }
)
# bnhack_sment: SpaceMouse Enterprise (31 buttons)
SPACEMOUSE_ENTERPRISE_BUTTONS = _by_report_bit(
    {
        256: 12,
        257: 13,
        258: 14,
        260: 15,
        261: 16,
        264: 17,
        266: 30,  # menu, fit, [T], [R], [F], [ ], iso
        268: 0,
        269: 1,
        270: 2,
        271: 3,
        272: 4,
        273: 5,
        274: 6,
        275: 7,
        276: 8,
        277: 9,  # 1..10
        278: 18,
        279: 19,
        280: 20,
        281: 21,
        282: 22,  # esc, alt, shift, ctrl, lock
        291: 23,
        292: 24,
        332: 10,
        333: 11,  # enter, delete, 11, 12
        358: 27,
        359: 28,
        360: 29,
        430: 25,
        431: 26,  # V1, V2, V3, tab, space
    }
)


@dataclass(frozen=True)
class Model:
    name: str
    newer_axes: bool
    # report-3 bit → button; None: the bit
    buttons: dict[int, int] | None = field(default=None, hash=False)


VENDOR_LOGITECH, VENDOR_3DCONNEXION = 0x046D, 0x256F

# spacenavd's usbdb, in its order.
MODELS: dict[tuple[int, int], Model] = {
    (0x046D, 0xC603): Model("SpaceMouse Plus XT", newer_axes=False),
    (0x046D, 0xC605): Model("CADman", newer_axes=True),
    (0x046D, 0xC606): Model("SpaceMouse Classic", newer_axes=False),
    (0x046D, 0xC621): Model("Spaceball 5000", newer_axes=True),
    (0x046D, 0xC623): Model("SpaceTraveler", newer_axes=True),
    (0x046D, 0xC625): Model("SpacePilot", newer_axes=True),
    (0x046D, 0xC626): Model("SpaceNavigator", newer_axes=True),
    (0x046D, 0xC627): Model("SpaceExplorer", newer_axes=True),
    (0x046D, 0xC628): Model("SpaceNavigator for Notebooks", newer_axes=True),
    (0x046D, 0xC629): Model("SpacePilot Pro", newer_axes=True),
    (0x046D, 0xC62B): Model("SpaceMouse Pro", newer_axes=True, buttons=SPACEMOUSE_PRO_BUTTONS),
    (0x046D, 0xC640): Model("NuLOOQ", newer_axes=False),
    (0x256F, 0xC62E): Model("SpaceMouse Wireless (cable)", newer_axes=True),
    (0x256F, 0xC62F): Model("SpaceMouse Wireless (receiver)", newer_axes=True),
    (0x256F, 0xC631): Model(
        "SpaceMouse Pro Wireless (cable)", newer_axes=True, buttons=SPACEMOUSE_PRO_BUTTONS
    ),
    (0x256F, 0xC632): Model(
        "SpaceMouse Pro Wireless (receiver)", newer_axes=True, buttons=SPACEMOUSE_PRO_BUTTONS
    ),
    (0x256F, 0xC633): Model(
        "SpaceMouse Enterprise", newer_axes=True, buttons=SPACEMOUSE_ENTERPRISE_BUTTONS
    ),
    (0x256F, 0xC635): Model("SpaceMouse Compact", newer_axes=True),
    (0x256F, 0xC636): Model("SpaceMouse Module", newer_axes=True),
    (0x256F, 0xC638): Model(
        "SpaceMouse Pro Wireless (Bluetooth, cable)",
        newer_axes=True,
        buttons=SPACEMOUSE_PRO_BUTTONS,
    ),
    (0x256F, 0xC63A): Model("SpaceMouse Wireless (Bluetooth)", newer_axes=True),
}

# The universal receiver is not in usbdb: spacenavd takes it by its vendor id, with the
# newer axis flags every 3Dconnexion-vendor device gets, and guesses what is behind it
# from the button count (more than 2: a SpaceMouse Pro Wireless).
UNIVERSAL_RECEIVER = (0x256F, 0xC652)
RECEIVER_NAME = "3Dconnexion Universal Receiver"
RECEIVER_PLAIN = Model("SpaceMouse Wireless (universal receiver)", newer_axes=True)
RECEIVER_PRO = Model(
    "SpaceMouse Pro Wireless (universal receiver)", newer_axes=True, buttons=SPACEMOUSE_PRO_BUTTONS
)

# devid_blacklist: same vendor, not 6-DoF devices.
NOT_SIX_DOF: dict[tuple[int, int], str] = {
    (0x256F, 0xC650): "CadMouse",
    (0x256F, 0xC651): "CadMouse Wireless",
    (0x256F, 0xC654): "CadMouse Pro Wireless",
    (0x256F, 0xC655): "CadMouse Compact",
    (0x256F, 0xC656): "CadMouse Pro",
    (0x256F, 0xC657): "CadMouse Pro Wireless Left",
    (0x256F, 0xC658): "CadMouse Compact Wireless",
    (0x256F, 0xC664): "Keyboard Pro",
    (0x256F, 0xC668): "Keyboard Pro (newer version)",
    (0x256F, 0xC665): "Numpad Pro",
    (0x256F, 0xC62C): "lipari(?)",
    (0x256F, 0xC641): "scout(?)",
}

# HID usage page 1 (Generic Desktop), usage 8: the multi-axis controller collection.
MULTI_AXIS_CONTROLLER = (0x01, 0x08)


def interface_usage(entry: dict) -> tuple[int, int] | None:
    """(usage page, usage) of a hidapi enumeration entry; None where the backend gives none."""
    page, usage = entry.get("usage_page"), entry.get("usage")
    return (page, usage) if page or usage else None


def receiver_model(button_count: int | None) -> Model:
    """What spacenavd guesses sits behind the universal receiver (None: count unknown)."""
    return RECEIVER_PRO if button_count is not None and button_count > 2 else RECEIVER_PLAIN


def is_six_dof(vendor_id: int, product_id: int, usage: tuple[int, int] | None = None) -> bool:
    """A device sasprobe takes: a listed model, or the universal receiver's 6-DoF interface.

    The receiver also carries a paired CadMouse (spacenavd skips its "Universal Receiver
    Mouse"); through hidapi that is another interface, so only the receiver's
    multi-axis controller interface counts.
    """
    ids = (vendor_id, product_id)
    if ids in MODELS:
        return True
    return ids == UNIVERSAL_RECEIVER and usage == MULTI_AXIS_CONTROLLER


def product_name(vendor_id: int, product_id: int) -> str:
    ids = (vendor_id, product_id)
    if ids in MODELS:
        return MODELS[ids].name
    if ids == UNIVERSAL_RECEIVER:
        return RECEIVER_NAME
    return NOT_SIX_DOF.get(ids, "HID device")


def refusal(vendor_id: int, product_id: int) -> str:
    """Why a device that is not a SpaceMouse model is refused (one line, naming it)."""
    ids = f"{vendor_id:04x}:{product_id:04x}"
    name = NOT_SIX_DOF.get((vendor_id, product_id))
    if name:
        return f"the 3Dconnexion {name} ({ids}) is not a 6-DoF device"
    if (vendor_id, product_id) == UNIVERSAL_RECEIVER:
        return (
            f"this interface of the {RECEIVER_NAME} ({ids}) is not its 6-DoF (multi-axis "
            "controller) one"
        )
    return f"{ids} is not a SpaceMouse model sasprobe knows (spacenavd's device list)"
