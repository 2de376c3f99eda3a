"""How many inputs a fuzz test draws: in the suite, a few hundred, the same every run (CI
stays deterministic); with SASPROBE_FUZZ=N in the environment, N fresh inputs each, the run
by the thousand outside the suite:

    SASPROBE_FUZZ=10000 .venv/bin/python -m pytest -p no:cacheprovider -o timeout=0 \\
        tests/test_molecule_structure_fuzz.py tests/test_daemon_recording_fuzz.py \\
        tests/test_daemon_control_hardening.py -k "fuzz or mangled"
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, Phase, settings

FUZZ = int(os.environ.get("SASPROBE_FUZZ", "0"))


def fuzz_settings(in_suite: int, inputs_per_example: int = 1) -> settings:
    """`in_suite` examples, or as many as make SASPROBE_FUZZ inputs where each example tries
    `inputs_per_example` of them."""
    return settings(
        max_examples=-(-FUZZ // inputs_per_example) or in_suite,
        derandomize=not FUZZ,
        deadline=None,
        database=None,
        suppress_health_check=list(HealthCheck),
        # no explain phase: its line tracing (Python < 3.12) makes a failing case take minutes
        phases=[p for p in Phase if p is not Phase.explain],
    )


class Seeds(list):
    """The files a fuzz test mangles (bytes), shown short: hypothesis prints a failing test's
    arguments."""

    def __repr__(self) -> str:
        return f"<{len(self)} seed files>"


def one_line_error(exc: BaseException) -> str:
    """The message of a user error as the CLI prints it; AssertionError when it is not one line."""
    message = str(exc)
    assert message and "\n" not in message, (
        f"a {type(exc).__name__} of more than one line: {message!r}"
    )
    return message


def cli_error_lines(stderr: str, failed: bool) -> list[str]:
    """The lines a terminal shows of a CLI's stderr (a progress bar redraws over itself after
    carriage returns), checked: warnings, and after them one error line when the command
    `failed`; never a traceback."""
    lines = [line.split("\r")[-1] for line in stderr.split("\n")]
    lines = [line for line in lines if line.strip()]
    assert "Traceback" not in stderr, stderr
    warnings = lines[:-1] if failed else lines
    assert all(line.startswith("sasprobe: warning: ") for line in warnings), stderr
    assert not failed or (lines and lines[-1].startswith("sasprobe: error: ")), stderr
    return lines
