"""One TOML file for everything the flags set.

Each `[section]` is a subcommand (`[daemon]`, `[render]`, ...) and each key one of its
long options, spelled as on the command line without the dashes (`probe-radius = 1.2`,
`device = "sim:scan"`, `headless = true`). Values go through the same checks as the
flags; flags given on the command line win over the file.

Where the file is found, first match wins: `--config FILE`, `$SASPROBE_CONFIG`,
`$XDG_CONFIG_HOME/sasprobe/config.toml` (default `~/.config/sasprobe/config.toml`).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from sasprobe.common.errors import UserError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


MAX_CONFIG_BYTES = 1 << 20


def default_path() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME")
    if not base:
        try:
            base = str(Path.home() / ".config")
        except (RuntimeError, KeyError):  # no $HOME and no passwd entry: there is no default file
            base = "~/.config"
    return Path(base) / "sasprobe" / "config.toml"


def find_config(explicit: str | None) -> Path | None:
    """The config file to use, or None. An explicitly named file must exist (load() checks what
    it is)."""
    for named, where in (
        (explicit, ""),
        (os.environ.get("SASPROBE_CONFIG"), " (from SASPROBE_CONFIG)"),
    ):
        if named:
            if not os.path.lexists(named):
                raise UserError(f"{named}: config file not found{where}")
            return Path(named)
    path = default_path()
    try:
        return path if path.exists() else None
    except OSError as exc:  # e.g. an unreadable $HOME: say so once and go on without a config file
        print(
            f"sasprobe: warning: cannot look for {path} "
            f"({exc.strerror or exc}); no config file used",
            file=sys.stderr,
        )
        return None


def load(path: Path) -> dict:
    from sasprobe.common.files import read_regular

    data = read_regular(path, MAX_CONFIG_BYTES, "config file")
    try:
        return tomllib.loads(data.decode("utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{path}: not valid TOML ({exc})") from None
    except UnicodeDecodeError as exc:
        raise UserError(f"{path}: cannot read ({exc})") from None


def _settable(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """Options a config file may set: every long option except help/version/config."""
    actions = {}
    for action in parser._actions:
        if isinstance(
            action, (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)
        ):
            continue
        long = [s for s in action.option_strings if s.startswith("--")]
        key = long[0][2:] if long else (action.dest if not action.option_strings else None)
        if key and key != "config":
            actions[key] = action
    return actions


def _convert(action: argparse.Action, value, where: str):
    def one(v):
        if isinstance(v, (dict, list)):
            raise UserError(f"{where}: expected a single value, got {type(v).__name__}")
        if action.type is not None:
            try:
                v = action.type(str(v))
            except (argparse.ArgumentTypeError, ValueError, TypeError) as exc:
                raise UserError(f"{where}: {exc}") from None
        if action.choices is not None and v not in action.choices:
            choices = ", ".join(map(str, action.choices))
            raise UserError(f"{where}: {v!r} is not one of {choices}")
        return v

    if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
        if not isinstance(value, bool):
            raise UserError(f"{where}: expected true or false")
        return value if isinstance(action, argparse._StoreTrueAction) else not value
    if (
        action.nargs in ("*", "+")
        or isinstance(action.nargs, int)
        or isinstance(action, argparse._AppendAction)
    ):
        values = value if isinstance(value, list) else [value]
        return [one(v) for v in values]
    return one(value)


def apply(path: Path, data: dict, commands: dict[str, argparse.ArgumentParser]) -> None:
    """Turn the file's values into defaults of the subcommand parsers (validated)."""
    for section, values in data.items():
        parser = commands.get(section)
        if parser is None:
            known = ", ".join(sorted(commands))
            raise UserError(f"{path}: unknown section [{section}] (sections are commands: {known})")
        if not isinstance(values, dict):
            raise UserError(f"{path}: '{section}' must be a [section] of options")
        settable = _settable(parser)
        for key, value in values.items():
            action = settable.get(key) or settable.get(key.replace("_", "-"))
            if action is None:
                known = ", ".join(sorted(settable)) or "none"
                raise UserError(f"{path}: [{section}] has no option '{key}' (options: {known})")
            parser.set_defaults(
                **{action.dest: _convert(action, value, f"{path}: [{section}] {key}")}
            )


def template(commands: dict[str, argparse.ArgumentParser]) -> str:
    """A commented config file listing every section and option with its default."""
    lines = [
        "# sasprobe configuration. Each [section] is a command, each key a long option.",
        f"# Default location: {default_path()} (or $SASPROBE_CONFIG, or --config FILE).",
        "# Uncomment and edit what you want to keep; command-line flags win.",
    ]
    for name in sorted(commands):
        settable = _settable(commands[name])
        settable.pop("template", None)  # `sasprobe config` itself
        if not settable:
            continue
        lines += ["", f"[{name}]"]
        for key, action in settable.items():
            default = action.default
            if default is argparse.SUPPRESS:
                continue
            if default is None:
                shown = "<value>"
            elif isinstance(default, bool):
                shown = "true" if default else "false"
            elif isinstance(default, (int, float)):
                shown = repr(default)
            else:
                shown = '"' + str(default).replace("\\", "\\\\").replace('"', '\\"') + '"'
            help_text = (action.help or "").replace("%(default)s", str(default)).replace("%%", "%")
            lines.append(f"# {key} = {shown}" + (f"    # {help_text}" if help_text else ""))
    return "\n".join(lines) + "\n"
