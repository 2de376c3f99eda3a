"""The layout's rules, read from the source: the dependency arrows between subsystems (and
inside daemon/ and render/), and the size of a module.

Every module under the folders pyproject.toml maps into `sasprobe.*` is parsed with `ast`
(imports inside functions count too), so a new subpackage (devices/<driver>/, say) is
checked without being listed here.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO_ROOT

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

# Which subsystems each may import (besides itself and the foundation below).
ALLOWED = {
    "protocol": set(),
    "molecule": set(),
    "devices": {"protocol", "molecule"},
    "daemon": {"devices", "molecule", "protocol"},
    "render": {"molecule", "protocol"},
}
# The root package `sasprobe/` has two floors: `sasprobe/common/` is the ground (the
# one-line user error, opening a user's file, the progress bar), which every layer may use
# and which imports nothing of ours but itself; `sasprobe/cli/` is the top (the command,
# its configuration and argument types, the demo, the benchmarks), which may import
# everything and which nothing imports. The package itself (its version) is ground too.
FOUNDATION_PACKAGE = "sasprobe.common"
CLI_PACKAGE = "sasprobe.cli"
ROOT_MODULES = {
    "sasprobe",
    "sasprobe.__main__",
}  # the version; `python -m sasprobe`, which runs the CLI
# Layers inside a subsystem: (package, what of its subsystem it may import besides itself).
INNER = {
    "sasprobe.daemon.haptics": set(),  # the tick's computation, below the process
    "sasprobe.render.gl": set(),  # GL plumbing, below the lighting and the passes
    "sasprobe.render.lighting": {"sasprobe.render.gl"},  # below the passes
}
# No clock, socket or thread in the haptic computation: it must replay bit for bit.
PURE = {
    "sasprobe.daemon.haptics": {
        "time",
        "socket",
        "threading",
        "zmq",
        "concurrent",
        "asyncio",
        "signal",
    }
}
MAX_LINES = 400
SIZE_REASON = "Size:"  # a longer module's docstring says why after this word


def package_dirs() -> dict[str, Path]:
    tool = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    return {name: REPO_ROOT / folder for name, folder in tool["package-dir"].items()}


def modules() -> dict[str, Path]:
    """Every module of the sasprobe namespace: import name -> file."""
    found = {}
    for package, root in package_dirs().items():
        for path in root.rglob("*.py"):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join([package, *parts])] = path
    return found


def imports_of(name: str, path: Path) -> list[tuple[str, int]]:
    """(absolute module name, line) of every import in a module; `from X import y` gives X.y
    as well as X, so importing a submodule by name is seen."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            out.append((base, node.lineno))
            out += [(f"{base}.{alias.name}", node.lineno) for alias in node.names]
    return out


def subsystem(module: str) -> str | None:
    """'daemon' for sasprobe.daemon.x, 'foundation', 'cli' for the rest of sasprobe.*, None outside."""
    parts = module.split(".")
    if parts[0] != "sasprobe":
        return None
    if len(parts) > 1 and parts[1] in ALLOWED:
        return parts[1]
    if module == "sasprobe" or within(module, FOUNDATION_PACKAGE):
        return "foundation"
    return "cli"


def within(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def resolve(name: str, known: set[str]) -> str | None:
    """The module an imported name lives in (`from X import y` names X.y), None if not ours."""
    while name:
        if name in known:
            return name
        name = name.rpartition(".")[0]
    return None


def violations(edges: list[tuple[str, str, int]], known: set[str]) -> list[str]:
    """The dependency rule over (importer, imported, line) edges; `known` are our module names."""
    problems = []
    for importer, imported, line in edges:
        imported = resolve(imported, known)
        if imported is None:
            continue  # third party or the standard library
        source, target = subsystem(importer), subsystem(imported)
        where = f"{importer} (line {line}) imports {imported}"
        if source == "cli":
            continue  # the CLI sits on top and may use everything
        if target == "cli":
            problems.append(f"{where}: nothing imports the CLI package")
        elif source == "foundation" and target not in (None, "foundation"):
            problems.append(f"{where}: the foundation imports nothing of ours")
        elif target not in (None, "foundation", source) and target not in ALLOWED[source]:
            problems.append(
                f"{where}: {source}/ may import only {', '.join(sorted(ALLOWED[source])) or 'nothing'}"
            )
        for layer, allowed in INNER.items():
            outer = layer.rpartition(".")[0]
            if (
                within(importer, layer)
                and within(imported, outer)
                and not within(imported, layer)
                and not any(within(imported, a) for a in allowed)
            ):
                problems.append(f"{where}: {layer} sits below the rest of {outer}")
    return problems


def test_dependencies_run_one_way():
    known = set(modules())
    edges = [
        (name, imported, line)
        for name, path in modules().items()
        for imported, line in imports_of(name, path)
    ]
    assert len(edges) > 500 and {subsystem(n) for n in known} >= set(ALLOWED) | {
        "cli",
        "foundation",
    }
    assert violations(edges, known) == []


@pytest.mark.parametrize(
    "edge, message",
    [
        (
            ("sasprobe.render.scene_state", "sasprobe.daemon.service", 1),
            "render/ may import only molecule, protocol",
        ),
        (
            ("sasprobe.devices.simulated", "sasprobe.daemon.haptics.engine", 1),
            "devices/ may import only",
        ),
        (
            ("sasprobe.protocol.pose", "sasprobe.molecule.grid", 1),
            "protocol/ may import only nothing",
        ),
        (
            ("sasprobe.daemon.service", "sasprobe.cli.argtypes", 1),
            "nothing imports the CLI package",
        ),
        (
            ("sasprobe.common.errors", "sasprobe.molecule", 1),
            "the foundation imports nothing of ours",
        ),
        (
            ("sasprobe.daemon.haptics.engine", "sasprobe.daemon.loop", 1),
            "sasprobe.daemon.haptics sits below",
        ),
        (
            ("sasprobe.render.gl.targets", "sasprobe.render.passes.base", 1),
            "sasprobe.render.gl sits below",
        ),
        (
            ("sasprobe.render.lighting.grid", "sasprobe.render.passes.base", 1),
            "sasprobe.render.lighting sits below",
        ),
    ],
)
def test_the_rule_catches_a_wrong_arrow(edge, message):
    known = set(modules())
    found = violations([edge], known)
    assert len(found) == 1 and message in found[0], found


def test_nothing_needs_the_cli_from_below_even_in_the_right_direction():
    known = set(modules())
    allowed = [
        ("sasprobe.cli.commands.render", "sasprobe.render.app", 1),
        ("sasprobe.daemon.service", "sasprobe.common.errors", 1),
        ("sasprobe.common.files", "sasprobe.common.errors", 1),
        ("sasprobe.render.link", "sasprobe.protocol.client", 1),
        ("sasprobe.daemon.service", "numpy", 1),
    ]
    assert violations(allowed, known) == []


def test_the_root_package_holds_only_its_two_floors():
    """Every module of sasprobe/ is on the ground floor (common/) or the top one (cli/)."""
    loose = [
        name
        for name in modules()
        if subsystem(name) in ("foundation", "cli")
        and name not in ROOT_MODULES
        and not within(name, FOUNDATION_PACKAGE)
        and not within(name, CLI_PACKAGE)
    ]
    assert loose == [], f"modules of sasprobe/ outside common/ and cli/: {loose}"


def test_the_haptic_computation_reads_no_clock_and_opens_no_socket_or_thread():
    for name, path in modules().items():
        for package, banned in PURE.items():
            if within(name, package):
                used = {imported.split(".")[0] for imported, _ in imports_of(name, path)}
                assert not used & banned, f"{name} imports {', '.join(sorted(used & banned))}"


def test_no_module_is_over_400_lines_without_saying_why():
    paths = list(modules().values()) + sorted((REPO_ROOT / "tests").rglob("*.py"))
    long = []
    for path in paths:
        lines = len(path.read_text().splitlines())
        if lines > MAX_LINES and SIZE_REASON not in (
            ast.get_docstring(ast.parse(path.read_text())) or ""
        ):
            long.append(f"{path.relative_to(REPO_ROOT)}: {lines} lines")
    assert long == [], (
        f"over {MAX_LINES} lines without '{SIZE_REASON} <why>' in the docstring: {long}"
    )


LAYOUT_PAGE = REPO_ROOT / "docs" / "architecture.md"


def layout_rows() -> list[str]:
    """The folders in the first column of the layout table in docs/architecture.md."""
    text = LAYOUT_PAGE.read_text()
    section = text[text.index("\n## Layout\n") :]
    end = section.find("\n## ", 1)
    section = section if end < 0 else section[:end]
    return [
        line.split("|")[1].strip().strip("`")
        for line in section.splitlines()
        if line.startswith("| `") and line.split("|")[1].strip().startswith("`")
    ]


def test_the_layout_table_matches_the_tree():
    import fnmatch

    rows = layout_rows()
    patterns = [re.sub(r"<[^>]+>", "*", row) for row in rows]
    for row in rows:
        if "<" not in row:  # a pattern row (devices/<driver>/) may match nothing yet
            assert (REPO_ROOT / row).is_dir(), (
                f"the layout table names {row}, which is not a folder"
            )
    folders = {
        f"{path.relative_to(REPO_ROOT).as_posix()}/"
        for root in package_dirs().values()
        for path in [root, *(init.parent for init in root.rglob("__init__.py"))]
    }
    folders.add("tests/")
    missing = sorted(
        f
        for f in folders
        if not any(fnmatch.fnmatch(f, p) and f.count("/") == p.count("/") for p in patterns)
    )
    assert missing == [], (
        f"packages the layout table of docs/architecture.md does not list: {missing}"
    )
