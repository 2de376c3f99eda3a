"""The folders map into sasprobe.* for editable and normal installs alike."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.conftest import REPO_ROOT

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 (tomli is a dependency there)
    import tomli as tomllib


def _pyproject() -> dict:
    return tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())


def test_every_package_folder_is_listed():
    tool = _pyproject()["tool"]["setuptools"]
    listed = set(tool["packages"])
    mapping = tool["package-dir"]
    found = set()
    for name, folder in mapping.items():
        root = REPO_ROOT / folder
        for init in root.rglob("__init__.py"):
            rel = init.parent.relative_to(root)
            found.add(".".join([name, *rel.parts]) if rel.parts else name)
    assert found == listed


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    result = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(REPO_ROOT)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    return next(out.glob("sasprobe-*.whl"))


def test_wheel_holds_the_namespace_and_data(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for module in (
        "sasprobe/cli/main.py",
        "sasprobe/common/errors.py",
        "sasprobe/molecule/grid.py",
        "sasprobe/devices/base.py",
        "sasprobe/protocol/pose.py",
        "sasprobe/molecule/data/1crn.pdb.gz",
        "sasprobe/protocol/README.md",
        *(
            f"sasprobe/protocol/schemas/{name}"
            for name in (
                "pose.json",
                "scene.schema.json",
                "control.schema.json",
                "device.schema.json",
                "control-record.schema.json",
                "events.schema.json",
            )
        ),
    ):
        assert module in names, module
    assert not any(
        n.startswith(("molecule/", "daemon/", "protocol/", "devices/", "render/")) for n in names
    )


def test_normal_install_imports_from_the_wheel(wheel, tmp_path):
    target = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "-q",
            "--target",
            str(target),
            str(wheel),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    code = (  # sasprobe.protocol.pose reads schemas/pose.json
        "import sasprobe.molecule as m, sasprobe.devices, sasprobe.protocol.pose; "
        "print(m.__file__); print(m.load_default().n_atoms)"
    )
    env = dict(os.environ, PYTHONPATH=str(target))
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    file_line, atoms = out.stdout.split()
    assert file_line.startswith(str(target)) and atoms == "327"
