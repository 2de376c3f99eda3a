"""`sasprobe`: one command with subcommands.

Each module in sasprobe/commands/ defines `register(subparsers)`; it is found here
without being listed, so adding a command touches one file.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys

import sasprobe.commands
from sasprobe import __version__, config
from sasprobe.errors import UserError


class OneLineParser(argparse.ArgumentParser):
    """Usage errors end in one line and exit status 2, like every other user error."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


class _StderrFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        return f"sasprobe: {record.levelname.lower()}: {record.getMessage()}"


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="sasprobe",
        description="Feel and see a protein's solvent accessible surface with a haptic arm.",
    )
    parser.add_argument("--version", action="version", version=f"sasprobe {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="print informational messages")
    parser.add_argument("--config", metavar="FILE", help=f"TOML settings (default: {config.default_path()} if present)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    for info in sorted(pkgutil.iter_modules(sasprobe.commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"sasprobe.commands.{info.name}")
        module.register(sub)
    return parser


def _configure_logging(verbose: bool) -> None:
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_StderrFormatter())
    root = logging.getLogger("sasprobe")
    root.handlers[:] = [handler]
    root.setLevel(logging.INFO if verbose else logging.WARNING)
    root.propagate = False


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _apply_config(parser: argparse.ArgumentParser, argv: list[str] | None) -> None:
    """Settings from the TOML file become defaults, so flags on the command line win."""
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--config")
    known, _ = pre.parse_known_args(argv)
    path = config.find_config(known.config)
    if path is not None:
        config.apply(path, config.load(path), subcommands(parser))


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        _apply_config(parser, argv)
    except UserError as exc:
        print(f"sasprobe: error: {exc}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    _configure_logging(args.verbose)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except UserError as exc:
        print(f"sasprobe: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("sasprobe: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `sasprobe info --json | head`
        return 0
