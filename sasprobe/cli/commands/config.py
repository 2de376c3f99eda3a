"""`sasprobe config`: where settings come from, and a template of every option."""

from __future__ import annotations

import argparse
import sys

from sasprobe.cli import config

HELP = "show the settings file in use, or print a template of every option"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("config", help=HELP)
    p.add_argument(
        "--template", action="store_true", help="print a commented TOML file listing every option"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.cli.main import build_parser, subcommands

    if args.template:
        sys.stdout.write(config.template(subcommands(build_parser())))
        return 0
    path = config.find_config(args.config)
    if path is None:
        print(
            f"no settings file (looked for $SASPROBE_CONFIG and {config.default_path()}); "
            "`sasprobe config --template` prints one to start from"
        )
        return 0
    print(f"# {path}")
    sys.stdout.write(path.read_text())
    return 0
