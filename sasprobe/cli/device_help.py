"""The list of --device schemes at the end of `sasprobe daemon --help`, `demo --help` and
`devices --help`: each scheme's name, one-line summary and example, read from the device
registry (devices/registry.py SCHEMES, plus the daemon's `replay`), so a driver
added there is listed without a change here."""

from __future__ import annotations

import argparse
import re
import textwrap


class TableHelpFormatter(argparse.HelpFormatter):
    """Fills the description and epilog line by line, so the epilog's table stays a table: a
    line `  name  text` wraps under its text, any other line under its own indent."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        lines = []
        for line in text.splitlines():
            column = re.match(r"\s*\S+\s{2,}", line) or re.match(r"\s*", line)
            lines.append(
                textwrap.fill(
                    line,
                    width,
                    initial_indent=indent,
                    subsequent_indent=indent + " " * column.end(),
                    break_on_hyphens=False,
                )
                if line.strip()
                else ""
            )
        return "\n".join(lines)


def device_schemes() -> dict:
    """name -> DeviceScheme of every --device scheme, the daemon's `replay` included."""
    from sasprobe.daemon.recording import replay_scheme
    from sasprobe.devices.registry import SCHEMES

    replay_scheme.register()
    return dict(SCHEMES)


def device_list() -> str:
    schemes = device_schemes()
    width = max(len(name) for name in schemes) + 2
    lines = ["devices (--device SCHEME[:ARGUMENT]; `sasprobe devices` lists what is plugged in):"]
    for name, scheme in schemes.items():
        lines.append(f"  {name:<{width}}{scheme.summary}")
        lines.append(f"  {'':<{width}}--device {scheme.example}")
    return "\n".join(lines)


def with_device_list() -> dict:
    """add_parser() options that end a command's help with the device list."""
    return {"epilog": device_list(), "formatter_class": TableHelpFormatter}
