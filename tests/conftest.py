"""Shared fixtures: the shared PDB structures and a helper to run the real CLI."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from sasprobe.paths import shared_structures

REPO_ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="session")
def shared_entries():
    entries = shared_structures()
    if not entries:
        pytest.skip("shared structures (../shared/data/pdb) are not beside this checkout")
    return entries


@pytest.fixture(scope="session")
def shared_by_id(shared_entries):
    return {e.id: e for e in shared_entries}


def run_cli(*args: str, timeout: float = 120, **kwargs) -> subprocess.CompletedProcess:
    """Run `sasprobe ARGS` as a user would (a real subprocess)."""
    env = dict(kwargs.pop("env", None) or os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run(
        [sys.executable, "-m", "sasprobe", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=kwargs.pop("cwd", REPO_ROOT),
        **kwargs,
    )
