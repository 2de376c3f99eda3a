"""The documentation against the code and the tree: every `sasprobe …` command line of
every page parses with the real argument parser, every `--option` a page names in inline
code is one a command has, every relative link (and its #anchor)
resolves, no page names a path outside the repository, and the README's set-up commands
are the ones CI runs.

Command lines are found in two places: shell lines in fenced code blocks (continuations
joined, `&&`, `&`, `|` and `;` split, redirections and comments dropped) and inline code
spans. A span may be a synopsis (`sasprobe devices [--json] [--check DEVICE [--seconds
S]]`): brackets are dropped, the first of `a|b` is taken, and an ALL-CAPS placeholder
after an option becomes a value that option accepts (its first choice, or the first
sample its type takes), so a synopsis is checked against the options the parser really
has.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import re
import sys
from pathlib import Path

import pytest

from sasprobe.cli.main import build_parser
from tests.conftest import REPO_ROOT
from tests.support.pages import (
    FENCE,
    PLACEHOLDER,
    SPAN,
    command_pages,
    pages,
    readme_commands,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 (tomli is a dependency there)
    import tomli as tomllib

SAMPLES = ("1", "64x48", "0,0,1", "0,0,1,1", "sim", "tcp://127.0.0.1:5555", "out.mp4")
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)\)")  # [text](target), ![alt](target)
UPWARD = re.compile(
    r"(?<![\w.])(?:\.\./)+[\w.-]*"
)  # ../x, ../../x: resolved against the page's folder
MACHINE_PATH = re.compile(r"(?<![\w.~])/work/")
OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
# Pages a command writes rather than a person: a link to one may precede its first run.
GENERATED = {"docs/benchmarks.md": "sasprobe bench --page docs/benchmarks.md"}


def subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def sample_value(action: argparse.Action, prefix: str = "") -> str:
    """A value the option accepts: its first choice, else the first sample its type takes
    (after `prefix`, for a placeholder inside a value such as `clutch=N`)."""
    if action.choices and not prefix:
        return str(next(iter(action.choices)))
    for sample in SAMPLES:
        try:
            (action.type or str)(prefix + sample)
            return prefix + sample
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
        option = current._option_string_actions.get(out[-1]) if out else None
        inner = re.fullmatch(r"([\w-]+=)(.+)", word)  # clutch=N
        if (
            option is not None
            and option.nargs != 0
            and inner
            and PLACEHOLDER.fullmatch(inner.group(2))
        ):
            word = sample_value(option, inner.group(1))
        elif PLACEHOLDER.fullmatch(word) or word == "...":
            if option is not None and option.nargs != 0:
                word = sample_value(option)
            elif subparsers(current) and word not in subparsers(current) and word != "...":
                word = next(iter(subparsers(current)))
            elif word == "...":
                continue
        out.append(word)
    return out


def exact_parser() -> argparse.ArgumentParser:
    """The real parser, taking options only as spelled in full: a page that wrote
    `--cube-half` must fail once the option is called anything else, even `--cube-halfedge`."""
    parser = build_parser()
    pending = [parser]
    while pending:
        current = pending.pop()
        current.allow_abbrev = False
        pending += subparsers(current).values()
    return parser


def parse_error(args: list[str]) -> str | None:
    """None when the parser accepts the arguments (or shows their --help), else its message."""
    parser = exact_parser()
    stderr = io.StringIO()
    try:
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
            parser.parse_args(fill_placeholders(parser, args))
    except SystemExit as exc:
        return None if exc.code == 0 else stderr.getvalue().strip() or f"exit status {exc.code}"
    return None


def every_option(parser: argparse.ArgumentParser, found: set[str] | None = None) -> set[str]:
    """The long options of the parser and of all its subcommands, at any depth."""
    found = set() if found is None else found
    for action in parser._actions:
        found.update(s for s in action.option_strings if s.startswith("--"))
    for sub in subparsers(parser).values():
        every_option(sub, found)
    return found


@functools.cache
def known_options() -> frozenset[str]:
    return frozenset(every_option(build_parser()))


def unknown_options(text: str) -> list[str]:
    """`--options` named in a page's inline code (option tables, prose) that no sasprobe
    command has: a renamed flag shows here even where no whole command line names it."""
    known = known_options()
    return [
        f"{option} in `{span}`"
        for span in SPAN.findall(FENCE.sub("", text))
        for option in OPTION.findall(span)
        if option not in known
    ]


def github_anchor(heading: str) -> str:
    """The id GitHub gives a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"[`*_]|\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip()).lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The #anchors of a page's headings (a repeated heading gets -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    out = set()
    for heading in re.findall(r"^#{1,6} +(.+?) *#*$", FENCE.sub("", page.read_text()), re.M):
        slug = github_anchor(heading)
        out.add(slug if slug not in seen else f"{slug}-{seen[slug]}")
        seen[slug] = seen.get(slug, 0) + 1
    return out


def link_problems(page: Path, text: str) -> list[str]:
    """Relative links of a page that lead nowhere: a missing file or a missing #anchor."""
    problems = []
    for target in LINK.findall(FENCE.sub("", text)):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        resolved = (page.parent / path).resolve() if path else page
        rel = (
            resolved.relative_to(REPO_ROOT).as_posix()
            if resolved.is_relative_to(REPO_ROOT)
            else None
        )
        if not resolved.exists():
            if rel not in GENERATED:
                problems.append(f"{target}: no such file")
            continue
        if anchor and resolved.suffix == ".md" and anchor not in anchors(resolved):
            problems.append(f"{target}: no heading #{anchor} in {rel}")
    return problems


def outside_paths(page: Path, text: str) -> list[str]:
    """Paths a page names that leave the repository (`../shared/...` from the root) or
    belong to one machine (`/work/...`)."""
    found = [f"{m.group(0)}: a path of one machine" for m in MACHINE_PATH.finditer(text)]
    for token in UPWARD.findall(text):
        if not (page.parent / token).resolve().is_relative_to(REPO_ROOT.resolve()):
            found.append(f"{token}: outside the repository")
    return found


def rel(page: Path) -> str:
    return page.relative_to(REPO_ROOT).as_posix()


def test_the_pages_are_found():
    names = {rel(p) for p in pages()}
    assert {
        "README.md",
        "CONTRIBUTING.md",
        "docs/architecture.md",
        "docs/connect-your-arm.md",
        "protocol/README.md",
        "devices/README.md",
    } <= names, names


@pytest.mark.parametrize("page", command_pages(), ids=rel)
def test_every_command_line_parses(page):
    commands = readme_commands(page.read_text())
    failures = [
        f"{where}: {error}" for where, args in commands if (error := parse_error(args)) is not None
    ]
    assert failures == []


@pytest.mark.parametrize("page", command_pages(), ids=rel)
def test_every_documented_option_exists(page):
    assert unknown_options(page.read_text()) == []


def test_the_command_lines_are_many():
    total = sum(len(readme_commands(p.read_text())) for p in command_pages())
    assert total >= 100, f"only {total} sasprobe command lines found: the extraction broke"


@pytest.mark.parametrize("page", pages(), ids=rel)
def test_every_relative_link_resolves(page):
    assert link_problems(page, page.read_text()) == []


@pytest.mark.parametrize("page", pages(), ids=rel)
def test_no_page_names_a_path_outside_the_repository(page):
    assert outside_paths(page, page.read_text()) == []


def test_generated_pages_name_a_command_that_writes_them():
    for page, command in GENERATED.items():
        ((_, args),) = readme_commands(f"`{command}`")
        assert parse_error(args) is None, (page, command)


def test_the_readme_set_up_commands_are_what_ci_runs():
    readme = (REPO_ROOT / "README.md").read_text()
    blocks = [block.strip() for block in FENCE.findall(readme)]
    demo = "python3 -m venv .venv && .venv/bin/pip install -q -e . && .venv/bin/sasprobe demo"
    tests = (
        "python3 -m venv .venv && .venv/bin/pip install -q -e '.[test]' "
        "&& .venv/bin/python -m pytest"
    )
    assert demo in blocks and tests in blocks
    assert tests in ci_commands(), "the README's test command is not what .ci/run runs"


def ci_commands() -> list[str]:
    """The lines of .ci/run that are not blank or comments, stripped."""
    return [
        line.strip()
        for line in (REPO_ROOT / ".ci" / "run").read_text().splitlines()
        if line.strip() and not line.lstrip().startswith("#")
    ]


def test_ci_fails_on_formatting_and_lint():
    """.ci/run stops at the first command that fails, and checks the formatting and the lint
    rules of the whole tree with the ruff the `test` extra installs, before the suite."""
    ci = ci_commands()
    installs = [i for i, line in enumerate(ci) if "pip install" in line and "test" in line]
    checks = [ci.index(".venv/bin/ruff format --check ."), ci.index(".venv/bin/ruff check .")]
    suite = next(i for i, line in enumerate(ci) if line.endswith("python -m pytest"))
    assert "set -euo pipefail" in ci
    assert installs and installs[0] < min(checks) and max(checks) < suite
    extras = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]
    assert any(req.startswith("ruff") for req in extras["optional-dependencies"]["test"])


@pytest.mark.parametrize(
    "text, error",
    [
        ("```sh\nsasprobe render --no-such-flag\n```\n", "unrecognized arguments: --no-such-flag"),
        (
            "```sh\nsasprobe daemon --duration 3   # the old name\n```\n",
            "unrecognized arguments: --duration",
        ),
        (
            "see `sasprobe render [--size WxH] [--frames N] [--nope]`\n",
            "unrecognized arguments: --nope",
        ),
        (
            "```sh\nsasprobe daemon & sasprobe render \\\n    --spheres cubes\n```\n",
            "invalid choice: 'cubes'",
        ),
        ("`sasprobe bench NAME --seconds S`", "unrecognized arguments: --seconds"),
        (
            "```sh\nsasprobe sas 1crn --per-atom > out.csv\n```\n",
            "unrecognized arguments: --per-atom",
        ),
        (
            "```sh\nsasprobe sas 1crn --per-res\n```\n",
            "unrecognized arguments: --per-res",
        ),  # no abbreviations
    ],
)
def test_a_wrong_line_is_caught(text, error):
    commands = readme_commands(text)
    errors = [parse_error(args) for _, args in commands]
    assert any(e is not None and error in e for e in errors), errors


def test_a_renamed_option_in_a_table_is_caught():
    table = (
        "| option | meaning |\n|---|---|\n| `--probe-light-reach Å` | the probe light's reach |\n"
    )
    assert unknown_options(table) == ["--probe-light-reach in `--probe-light-reach Å`"]
    assert unknown_options(table.replace("reach Å", "range Å")) == []


def test_a_redirection_is_the_shells():
    ((_, args),) = readme_commands("```sh\nsasprobe sas 1crn --csv > out.csv 2>&1\n```\n")
    assert args == ["sas", "1crn", "--csv"] and parse_error(args) is None


def test_synopses_become_real_command_lines():
    parser = build_parser()
    ((_, args),) = readme_commands("`sasprobe devices [--json] [--check DEVICE [--seconds S]]`")
    assert fill_placeholders(parser, args) == [
        "devices",
        "--json",
        "--check",
        "1",
        "--seconds",
        "1",
    ]
    ((_, args),) = readme_commands("`sasprobe bench NAME --help`")
    assert (
        fill_placeholders(parser, args)[:1] == ["bench"]
        and fill_placeholders(parser, args)[2] == "--help"
    )


@pytest.mark.parametrize(
    "text, problem",
    [
        ("[the daemon](docs/no-such-page.md)", "no such file"),
        ("![a chart](docs/figures/no-such-chart.png)", "no such file"),
        ("[safety](docs/daemon.md#no-such-heading)", "no heading #no-such-heading"),
        ("[here](#nowhere)", "no heading #nowhere"),
    ],
)
def test_a_broken_link_is_caught(text, problem):
    found = link_problems(REPO_ROOT / "README.md", text)
    assert len(found) == 1 and problem in found[0], found


def test_a_working_link_and_a_web_link_pass():
    text = "[safety](docs/daemon.md#safety), [arm](docs/connect-your-arm.md#a-pulled-cable), [mcap](https://mcap.dev)"
    assert link_problems(REPO_ROOT / "README.md", text) == []


@pytest.mark.parametrize(
    "page, text, caught",
    [
        ("README.md", "the structures in `../shared/data/pdb/`", True),
        ("docs/viewing.md", "see ../../shared/research/haptics.md", True),
        ("docs/viewing.md", "a checkout in /work/main", True),
        ("docs/viewing.md", "[protocol](../protocol/README.md)", False),
        ("README.md", "`tests/data/pdb/1aon.pdb.gz`", False),
    ],
)
def test_a_path_outside_the_repository_is_caught(page, text, caught):
    assert bool(outside_paths(REPO_ROOT / page, text)) == caught


# Environment variables the code reads that are not settings of sasprobe: passed on to children.
NOT_SETTINGS = {"PYTHONPATH": "sasprobe bench hands it on to the emulators' processes"}
ENV_READ = re.compile(
    r"""(?:environ\.get|environ\.setdefault|env\.setdefault|getenv|factory_from_environment)"""
    r"""\(\s*["']([A-Z][A-Z0-9_]+)["']|environ\[\s*["']([A-Z][A-Z0-9_]+)["']\]"""
    r"""|^[A-Z_]*ENV\s*=\s*["']([A-Z][A-Z0-9_]+)["']""",
    re.M,
)


def environment_variables_read() -> set[str]:
    """Every environment variable the installed code reads by name."""
    folders = ("molecule", "protocol", "devices", "daemon", "render", "sasprobe")
    found = set()
    for folder in folders:
        for path in (REPO_ROOT / folder).rglob("*.py"):
            for match in ENV_READ.finditer(path.read_text()):
                found.update(name for name in match.groups() if name)
    return found


def test_every_environment_variable_is_documented():
    """docs/configuration.md names every variable the code reads (its table, or the test
    hooks under it)."""
    read = environment_variables_read()
    assert {"SASPROBE_PDB_MIRROR", "SASPROBE_HD_LIBRARY", "LP_NUM_THREADS"} <= read, read
    page = (REPO_ROOT / "docs" / "configuration.md").read_text()
    documented = set(re.findall(r"`([A-Z][A-Z0-9_]+)(?:=[^`]*)?`", page))
    assert sorted(read - documented - set(NOT_SETTINGS)) == []
