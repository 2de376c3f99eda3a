"""The layout's rules, read from the source: the dependency arrows between subsystems (and
inside daemon/ and render/), no import circle, only passes in render/passes/, the layout
table of docs/architecture.md, and a soft guide to a module's size (no block written twice:
test_project_repeats.py).

Every module under the folders pyproject.toml maps into `sasprobe.*` is parsed with `ast`
(imports inside functions count too), so a new subpackage (devices/<driver>/, say) is
checked without being listed here. Each rule has a test that feeds it a made-up
violation, so a rule that stopped seeing one would fail.
"""

from __future__ import annotations

import ast
import re
import sys
import warnings
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
    "web": {"molecule", "protocol"},
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
    # Following a daemon fills in the scene and draws nothing: no GL, no pass, no window.
    "sasprobe.render.follow": {"sasprobe.render.scene_state", "sasprobe.render.source"},
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
# A module is split where a job ends, not at a line count: past SOFT_LINES a module is
# reported (a warning in the test summary) as worth a look for a second job; past
# HARD_LINES it fails.
SOFT_LINES = 600
HARD_LINES = 1000


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
    return imports_in(name, path.name == "__init__.py", path.read_text(), str(path))


def imports_in(
    name: str, is_package: bool, source: str, filename: str = "<source>"
) -> list[tuple[str, int]]:
    """imports_of for a module's source text."""
    package = name if is_package else name.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(source, filename)):
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
    """'daemon' for sasprobe.daemon.x, 'foundation', 'cli' for the rest of sasprobe.*, None
    outside."""
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
            may = ", ".join(sorted(ALLOWED[source])) or "nothing"
            problems.append(f"{where}: {source}/ may import only {may}")
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
            ("sasprobe.render.lighting.culling", "sasprobe.render.passes.base", 1),
            "sasprobe.render.lighting sits below",
        ),
        (
            ("sasprobe.render.follow.daemon_source", "sasprobe.render.gl.context", 1),
            "sasprobe.render.follow sits below",
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
        ("sasprobe.render.follow.daemon_source", "sasprobe.protocol.client", 1),
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


class LongModule(UserWarning):
    """A module past the soft guide: worth a look for a second job in it."""


def size_findings(lengths: dict[str, int]) -> tuple[list[str], list[str]]:
    """(modules past the soft guide, modules past the hard limit) of {path: line count}."""
    soft = [f"{p}: {n} lines" for p, n in lengths.items() if SOFT_LINES < n <= HARD_LINES]
    hard = [f"{p}: {n} lines" for p, n in lengths.items() if n > HARD_LINES]
    return soft, hard


def test_modules_stay_a_readable_size():
    paths = list(modules().values()) + sorted((REPO_ROOT / "tests").rglob("*.py"))
    lengths = {
        path.relative_to(REPO_ROOT).as_posix(): len(path.read_text().splitlines()) for path in paths
    }
    soft, hard = size_findings(lengths)
    for finding in soft:
        warnings.warn(f"{finding}: past {SOFT_LINES}, does it hold two jobs?", LongModule, 1)
    assert hard == [], f"modules over {HARD_LINES} lines: split them where a job ends: {hard}"


def test_the_size_guide_warns_then_fails():
    soft, hard = size_findings({"a.py": 400, "b.py": 601, "c.py": 1000, "d.py": 1001})
    assert soft == ["b.py: 601 lines", "c.py: 1000 lines"] and hard == ["d.py: 1001 lines"]


# ---------------------------------------------------------------- import circles
def import_graph(sources: dict[str, tuple[bool, str]]) -> dict[str, dict[str, int]]:
    """{module: {module it imports: line}} over our modules, from {name: (is a package's
    __init__, source)}. `from pkg import mod` imports pkg (its __init__ runs first and is
    looked up) as well as pkg.mod; `from pkg.mod import x` imports pkg.mod alone."""
    known = set(sources)
    graph: dict[str, dict[str, int]] = {name: {} for name in sources}
    for name, (is_package, source) in sources.items():
        for imported, line in imports_in(name, is_package, source, name):
            target = resolve(imported, known)
            if target is not None and target != name:
                graph[name].setdefault(target, line)
    return graph


def circles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The import circles: the strongly connected components of more than one module
    (Tarjan's algorithm, iterative), each sorted, in order of their first module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, edges = work[-1]
            step = next(edges, None)
            if step is not None:
                if step not in index:
                    index[step] = low[step] = len(index)
                    stack.append(step)
                    on_stack.add(step)
                    work.append((step, iter(sorted(graph[step]))))
                elif step in on_stack:
                    low[node] = min(low[node], index[step])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return sorted(found)


def describe_circle(circle: list[str], graph: dict[str, dict[str, int]]) -> str:
    """One circle as the imports that close it: `a (line 3) -> b`, ..."""
    members = set(circle)
    arrows = [
        f"{name} (line {line}) -> {target}"
        for name in circle
        for target, line in sorted(graph[name].items())
        if target in members
    ]
    return "; ".join(arrows)


def sources_of(found: dict[str, Path]) -> dict[str, tuple[bool, str]]:
    return {name: (path.name == "__init__.py", path.read_text()) for name, path in found.items()}


def test_no_import_circle():
    """No module imports one that imports it back, directly or through others (imports inside
    functions and under TYPE_CHECKING count): a circle makes the import order matter and
    hides which of the two is the lower layer."""
    graph = import_graph(sources_of(modules()))
    found = [describe_circle(c, graph) for c in circles(graph)]
    assert found == [], "import circles:\n" + "\n".join(found)


@pytest.mark.parametrize(
    "sources, expected",
    [
        (  # a -> b -> c -> a, the last one inside a function
            {
                "x.a": (False, "import x.b\n"),
                "x.b": (False, "from x.c import f\n"),
                "x.c": (False, "def f():\n    from x import a\n"),
                "x": (True, ""),
            },
            [["x.a", "x.b", "x.c"]],
        ),
        (  # a package that re-exports its driver, whose driver imports a sibling by the package
            {
                "p": (True, "from p.driver import Device\n"),
                "p.driver": (False, "from p import models\n"),
                "p.models": (False, "LIMIT = 1\n"),
            },
            [["p", "p.driver"]],
        ),
        (  # the same, the sibling named by its own module, and a relative import: no circle
            {
                "p": (True, "from p.driver import Device\n"),
                "p.driver": (False, "from p.models import LIMIT\nfrom .models import LIMIT\n"),
                "p.models": (False, "LIMIT = 1\n"),
            },
            [],
        ),
        (  # a relative `from . import x` in a package's module imports the package
            {
                "p": (True, "from .driver import Device\n"),
                "p.driver": (False, "from . import models\n"),
                "p.models": (False, ""),
            },
            [["p", "p.driver"]],
        ),
        (  # a type-only import closes a circle too
            {
                "m.a": (False, "from m.b import B\n"),
                "m.b": (
                    False,
                    "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from m.a import A\n",
                ),
            },
            [["m.a", "m.b"]],
        ),
    ],
)
def test_a_circle_is_caught(sources, expected):
    graph = import_graph(sources)
    assert circles(graph) == expected
    for circle in expected:
        assert " -> " in describe_circle(circle, graph)


# ---------------------------------------------------------------- render/passes/ holds passes
PASSES = REPO_ROOT / "render" / "passes"
PASS_BASE = "Pass"  # render/passes/base.py
NOT_PASSES = {"__init__", "base"}  # the package, and the base class with the frame it reads


def modules_without_a_pass(sources: dict[str, str]) -> list[str]:
    """The modules of {name: source} that define no subclass of Pass, directly or through
    another pass class of these modules."""
    classes = {}  # class name -> names of its bases
    for source in sources.values():
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.ClassDef):
                classes[node.name] = {
                    base.id if isinstance(base, ast.Name) else base.attr
                    for base in node.bases
                    if isinstance(base, ast.Name | ast.Attribute)
                }
    passes = {PASS_BASE}
    while grown := {n for n, bases in classes.items() if bases & passes and n not in passes}:
        passes |= grown
    return sorted(
        name
        for name, source in sources.items()
        if not any(
            isinstance(node, ast.ClassDef) and node.name in passes - {PASS_BASE}
            for node in ast.walk(ast.parse(source))
        )
    )


def test_render_passes_holds_only_passes():
    sources = {
        path.relative_to(PASSES).with_suffix("").as_posix(): path.read_text()
        for path in sorted(PASSES.rglob("*.py"))
        if path.stem not in NOT_PASSES
    }
    assert len(sources) > 5
    loose = modules_without_a_pass(sources)
    assert loose == [], (
        f"modules of render/passes/ that define no {PASS_BASE} (render/passes/base.py): "
        f"{loose}; a helper belongs beside what uses it, outside the passes"
    )


def test_a_module_that_is_not_a_pass_is_caught():
    sources = {
        "spheres": "from sasprobe.render.passes.base import Pass\n"
        "class SpherePass(Pass):\n    pass\n",
        "wide": "from sasprobe.render.passes import spheres\n"
        "class WideSpherePass(spheres.SpherePass):\n    pass\n",
        "lit": "class Layers:\n    pass\nclass LitPass(Layers, base.Pass):\n    pass\n",
        "mixin": "class Layers:\n    def _sync(self):\n        pass\n",
        "overlay": "def draw_text(frame):\n    pass\n",
    }
    assert modules_without_a_pass(sources) == ["mixin", "overlay"]
