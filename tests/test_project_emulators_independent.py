"""Emulators are oracles: no module in tests/emulators/ may import from the package it checks.

Each emulator is written from the makers' public firmware and host code; importing a
driver's tables, codecs or kinematics would mirror its mistakes on both sides. Every
import statement is checked (module level or inside a function), and so are imports of
other test modules, which may themselves import the package.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

EMULATORS = Path(__file__).parent / "emulators"
MODULES = sorted(EMULATORS.glob("*.py"))


def imported_names(source: str) -> list[str]:
    names = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append(node.module)
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", ""))
            in ("import_module", "__import__")
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            names.append(str(node.args[0].value))
    return names


def forbidden(name: str) -> bool:
    top = name.split(".")[0]
    return top in ("sasprobe", "molecule", "devices", "daemon", "protocol", "render") or (
        top == "tests" and not (name == "tests.emulators" or name.startswith("tests.emulators."))
    )


@pytest.mark.parametrize("module", MODULES, ids=lambda p: p.stem)
def test_emulator_imports_nothing_from_sasprobe(module):
    bad = [name for name in imported_names(module.read_text()) if forbidden(name)]
    assert not bad, f"tests/emulators/{module.name} imports {', '.join(bad)}"


def test_the_check_sees_every_kind_of_import():
    source = (
        "import sasprobe.devices\nfrom tests.device_loop import run\n"
        "def f():\n    from sasprobe.devices.falcon import x\n"
        "    importlib.import_module('sasprobe.daemon')\n"
        "from tests.emulators.physics import HeldStylus\nimport numpy\n"
    )
    assert [n for n in imported_names(source) if forbidden(n)] == [
        "sasprobe.devices",
        "tests.device_loop",
        "sasprobe.devices.falcon",
        "sasprobe.daemon",
    ]
