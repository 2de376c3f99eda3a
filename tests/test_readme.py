"""Every `sasprobe …` command line of the README parses with the real argument parser.

Found in two places: shell lines in fenced code blocks (continuations joined, `&&`, `&`,
`|` and `;` split, comments dropped) and inline code spans. A span may be a synopsis
(`sasprobe devices [--json] [--check DEVICE [--seconds S]]`): brackets are dropped, the
first of `a|b` is taken, and an ALL-CAPS placeholder after an option becomes a value that
option accepts (its first choice, or the first sample its type takes), so a synopsis is
checked against the options the parser really has.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex

import pytest

from sasprobe.cli.main import build_parser
from tests.conftest import REPO_ROOT

FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.M | re.S)
SPAN = re.compile(r"`([^`]+)`")  # inline code, paired left to right
OPERATOR = re.compile(r"\s(?:&&|\|\||[&|;])(?:\s|$)|\s&$")
PLACEHOLDER = re.compile(r"[A-Z][A-Z0-9_]*(\.[a-z0-9]+)?|WxH|[A-Z](,[A-Z])+")
SAMPLES = ("1", "64x48", "0,0,1", "0,0,1,1", "sim", "tcp://127.0.0.1:5555", "out.mp4")


def sasprobe_args(words: list[str]) -> list[str] | None:
    """The arguments after `sasprobe` (also `.venv/bin/sasprobe`, `python -m sasprobe`), or None."""
    for i, word in enumerate(words):
        if word == "sasprobe" or word.endswith("/sasprobe"):
            if i == 0 or words[i - 1] == "-m":
                return words[i + 1:]
    return None


def commands_in(line: str) -> list[list[str]]:
    """The sasprobe invocations of one shell line."""
    found = []
    for part in OPERATOR.split(line):
        args = sasprobe_args(shlex.split(part, comments=True))
        if args is not None:
            found.append(args)
    return found


def readme_commands(text: str) -> list[tuple[str, list[str]]]:
    """(where, arguments) of every sasprobe command line in a README's text."""
    found = []
    for block in FENCE.findall(text):
        for line in block.replace("\\\n", " ").splitlines():
            found += [(f"code: {line.strip()}", args) for args in commands_in(line)]
    for span in SPAN.findall(FENCE.sub("", text)):
        if "sasprobe " not in span or "\n\n" in span:
            continue
        span = " ".join(span.split())  # a span may wrap over two lines
        found += [(f"`{span}`", synopsis(args)) for args in commands_in(span)]
    return found


def synopsis(args: list[str]) -> list[str]:
    """A synopsis as plain words: no brackets, first alternatives (`...` stays a placeholder)."""
    words = []
    for word in args:
        word = word.replace("[", "").replace("]", "")
        if "|" in word.strip("|"):
            word = word.split("|")[0]
        if word:
            words.append(word)
    return words


def subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def sample_value(action: argparse.Action) -> str:
    """A value the option accepts: its first choice, else the first sample its type takes."""
    if action.choices:
        return str(next(iter(action.choices)))
    for sample in SAMPLES:
        try:
            (action.type or str)(sample)
            return sample
        except (argparse.ArgumentTypeError, ValueError, TypeError):
            continue
    raise AssertionError(f"no sample value for {action.option_strings}")


def fill_placeholders(parser: argparse.ArgumentParser, args: list[str]) -> list[str]:
    """Placeholders (and `...`) after options become values those options accept; a
    placeholder where a subcommand is expected becomes its first subcommand; any other
    `...` (more options) is dropped."""
    out = []
    for word in args:
        current = parser
        for earlier in out:  # descend into the subcommands named so far
            current = subparsers(current).get(earlier, current)
        if PLACEHOLDER.fullmatch(word) or word == "...":
            option = current._option_string_actions.get(out[-1]) if out else None
            if option is not None and option.nargs != 0:
                word = sample_value(option)
            elif subparsers(current) and word not in subparsers(current) and word != "...":
                word = next(iter(subparsers(current)))
            elif word == "...":
                continue
        out.append(word)
    return out


def parse_error(args: list[str]) -> str | None:
    """None when the parser accepts the arguments (or shows their --help), else its message."""
    parser = build_parser()
    stderr = io.StringIO()
    try:
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
            parser.parse_args(fill_placeholders(parser, args))
    except SystemExit as exc:
        return None if exc.code == 0 else stderr.getvalue().strip() or f"exit status {exc.code}"
    return None


def test_every_readme_command_line_parses():
    commands = readme_commands((REPO_ROOT / "README.md").read_text())
    assert len(commands) >= 50, f"only {len(commands)} sasprobe command lines found: the extraction broke"
    failures = [f"{where}: {error}" for where, args in commands if (error := parse_error(args)) is not None]
    assert failures == []


@pytest.mark.parametrize("text, error", [
    ("```sh\nsasprobe render --no-such-flag\n```\n", "unrecognized arguments: --no-such-flag"),
    ("```sh\nsasprobe daemon --duration 3   # the old name\n```\n", "unrecognized arguments: --duration"),
    ("see `sasprobe render [--size WxH] [--frames N] [--nope]`\n", "unrecognized arguments: --nope"),
    ("```sh\nsasprobe daemon & sasprobe render \\\n    --spheres cubes\n```\n", "invalid choice: 'cubes'"),
    ("`sasprobe bench NAME --seconds S`", "unrecognized arguments: --seconds"),
])
def test_a_wrong_line_is_caught(text, error):
    commands = readme_commands(text)
    errors = [parse_error(args) for _, args in commands]
    assert any(e is not None and error in e for e in errors), errors


def test_synopses_become_real_command_lines():
    parser = build_parser()
    (_, args), = readme_commands("`sasprobe devices [--json] [--check DEVICE [--seconds S]]`")
    assert fill_placeholders(parser, args) == ["devices", "--json", "--check", "1", "--seconds", "1"]
    (_, args), = readme_commands("`sasprobe bench NAME --help`")
    assert fill_placeholders(parser, args)[:1] == ["bench"] and fill_placeholders(parser, args)[2] == "--help"
