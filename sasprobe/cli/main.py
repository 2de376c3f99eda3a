"""`sasprobe`: one command with subcommands.

Each module in sasprobe/cli/commands/ defines `register(subparsers)`; it is found here
without being listed, so adding a command touches one file. A module that also defines
`HELP` (its one-line summary) and keeps its heavy imports inside functions is only
registered in full when it runs (or a config file has its section): `sasprobe --help`
then lists it without importing numpy, gemmi, GL or plotting libraries.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import sys

import sasprobe.cli.commands
from sasprobe.cli import config
from sasprobe.common.errors import UserError


class OneLineParser(argparse.ArgumentParser):
    """Usage errors end in one line and exit status 2, like every other user error."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


class _StderrFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        return f"sasprobe: {record.levelname.lower()}: {record.getMessage()}"


class _Version(argparse.Action):
    """--version, with the version looked up only when asked (importlib.metadata is slow to
    import)."""

    def __init__(
        self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None
    ):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from sasprobe import __version__

        parser.exit(message=f"sasprobe {__version__}\n")


def command_names() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(sasprobe.cli.commands.__path__))


def build_parser(full: set[str] | None = None) -> argparse.ArgumentParser:
    """The CLI's parser; the commands in `full` (default: all) with every option, the
    others that define HELP only by name and summary."""
    parser = OneLineParser(
        prog="sasprobe",
        description="Feel and see a protein's solvent accessible surface with a haptic arm.",
    )
    parser.add_argument("--version", action=_Version, help="show the version and exit")
    parser.add_argument("-v", "--verbose", action="store_true", help="print informational messages")
    parser.add_argument(
        "--config",
        metavar="FILE",
        help=f"TOML settings (default: {config.default_path()} if present)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    for name in command_names():
        module = importlib.import_module(f"sasprobe.cli.commands.{name}")
        if full is None or name in full or not hasattr(module, "HELP"):
            module.register(sub)
        else:
            sub.add_parser(name, help=module.HELP)
    return parser


def invoked_command(argv: list[str]) -> str | None:
    """The subcommand a command line runs (the first word that is not a global option)."""
    names = set(command_names())
    skip = False
    for word in argv:
        if skip:
            skip = False
        elif word == "--config":
            skip = True
        elif not word.startswith("-"):
            return word if word in names else None
    return None


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


def _config_file(argv: list[str]) -> tuple:
    """(path, contents) of the TOML settings in use, or (None, {})."""
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--config")
    known, _ = pre.parse_known_args(argv)
    path = config.find_config(known.config)
    return (path, config.load(path)) if path is not None else (None, {})


def one_blas_thread() -> None:
    """numpy's BLAS on one thread unless the user chose otherwise; effective only before
    numpy loads (commands import it when they run). OpenBLAS's threads spin on after each
    product, and the products here are small, so they took the CPU the renderer's llvmpipe
    threads and the haptic loop need. Child processes inherit it."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main(argv: list[str] | None = None) -> int:
    one_blas_thread()
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        path, settings = _config_file(argv)
        parser = build_parser(full={invoked_command(argv), *settings})
        if path is not None:  # the file's values become defaults, so flags on the command line win
            config.apply(path, settings, subcommands(parser))
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
