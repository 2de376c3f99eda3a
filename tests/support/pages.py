"""The Markdown pages a reader meets and the `sasprobe` command lines in them: shell lines of
fenced code blocks (continuations joined, `&&`, `&`, `|` and `;` split, redirections and
comments set apart) and inline code spans (a span may be a synopsis: `[--json]`, `a|b`,
ALL-CAPS placeholders).

tests/test_project_readme.py parses every one with the real argument parser;
tests/test_project_pages_run.py runs them.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

from tests.conftest import REPO_ROOT

FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.M | re.S)
SPAN = re.compile(r"`([^`]+)`")  # inline code, paired left to right
OPERATOR = re.compile(r"\s(?:&&|\|\||[&|;])(?:\s|$)|\s&$")
REDIRECTION = re.compile(r"\d*[<>]")  # `> out.csv`, `2>&1`: the shell's, not the command's
PLACEHOLDER = re.compile(r"[A-Z][A-Z0-9_]*(\.[a-z0-9]+)?|WxH|[A-Z](,[A-Z])+")


def pages() -> list[Path]:
    """The Markdown pages a reader meets: the README, CONTRIBUTING, CHANGELOG, docs/ and the
    subsystems' own READMEs."""
    found = [REPO_ROOT / name for name in ("README.md", "CONTRIBUTING.md", "CHANGELOG.md")]
    found += sorted((REPO_ROOT / "docs").glob("*.md"))
    found += sorted(REPO_ROOT.glob("[!.]*/README.md")) + sorted(
        (REPO_ROOT / "tests" / "data").rglob("README.md")
    )
    return [p for p in dict.fromkeys(found) if p.is_file()]


def command_pages() -> list[Path]:
    """Pages whose command lines must parse today (the changelog's describe past versions)."""
    return [p for p in pages() if p.name != "CHANGELOG.md"]


def sasprobe_args(words: list[str]) -> list[str] | None:
    """The arguments after `sasprobe` (also `.venv/bin/sasprobe`, `python -m sasprobe`), or None."""
    for i, word in enumerate(words):
        if word == "sasprobe" or word.endswith("/sasprobe"):
            if i == 0 or words[i - 1] == "-m":
                args = words[i + 1 :]
                cut = next((k for k, w in enumerate(args) if REDIRECTION.match(w)), len(args))
                return args[:cut]
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
    """(where, arguments) of every sasprobe command line in a page's text."""
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


class Line:
    """One `sasprobe` invocation of a page, as a shell would run it."""

    def __init__(
        self,
        page: str,
        text: str,
        args: list[str],
        background: bool = False,
        stdout_to: str | None = None,
        block: int | None = None,
    ) -> None:
        self.page = page  # relative to the repository
        self.text = text  # as the page writes it, blanks collapsed, comment included
        self.args = list(args)  # the words after `sasprobe`
        self.background = background  # followed by `&`
        self.stdout_to = stdout_to  # `> FILE`
        self.block = block  # the fenced block's index; None for an inline span

    def __repr__(self) -> str:
        return f"{self.page}: {self.text}"


def split_comment(line: str) -> tuple[str, str]:
    """(code, comment) of a shell line: the comment starts at an unquoted `#` after a blank."""
    quote = None
    for i, char in enumerate(line):
        if quote:
            quote = None if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].rstrip(), line[i + 1 :].strip()
    return line.rstrip(), ""


def _invocation(words: list[str]) -> tuple[list[str], str | None] | None:
    """(the arguments after `sasprobe`, the file stdout goes to) of one command, or None."""
    args = sasprobe_args(words)
    if args is None:
        return None
    rest = words[len(words) - len(args) :] if args else []
    stdout_to = None
    for k, word in enumerate(rest):
        if word in (">", "1>") and k + 1 < len(rest):
            stdout_to = rest[k + 1]
        elif re.fullmatch(r"1?>[^&].*", word):
            stdout_to = word.split(">", 1)[1]
    return args, stdout_to


def page_lines(page: Path) -> list[Line]:
    """Every `sasprobe` invocation of a page in reading order: each fenced block's lines,
    then the inline spans."""
    text = page.read_text()
    name = page.relative_to(REPO_ROOT).as_posix()
    found = []
    for index, block in enumerate(FENCE.findall(text)):
        for raw in block.replace("\\\n", " ").splitlines():
            code, _ = split_comment(raw)
            parts = re.split(r"\s(&&|\|\||[&|;])(?=\s|$)", code)
            for k in range(0, len(parts), 2):
                invocation = _invocation(shlex.split(parts[k]))
                if invocation is None:
                    continue
                background = k + 1 < len(parts) and parts[k + 1] == "&"
                found.append(
                    Line(
                        name, " ".join(raw.split()), invocation[0], background, invocation[1], index
                    )
                )
    for span in SPAN.findall(FENCE.sub("", text)):
        if "sasprobe " not in span or "\n\n" in span:
            continue
        span = " ".join(span.split())
        found += [Line(name, span, args) for args in commands_in(span)]
    return found
