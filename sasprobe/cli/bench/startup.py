"""`sasprobe bench startup`: how long the CLI takes to start, and what it imports.

Each command runs as a fresh process (`python -m sasprobe ...`) as a user's shell would
start it, the commands taking turns; the figure is the median wall time. A bare
`python -c pass` and `import numpy` give the floor in the same run. Target: `sasprobe
--help` within 0.3 s. The modules each command loaded are listed from the process itself
(sys.modules at exit), so a plotting or GL library that `--help` or `info` does not use
shows up here.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time

from sasprobe.cli.bench import BenchContext, BenchResult

TITLE = "CLI start-up: sasprobe --help and sasprobe info"
HELP_TARGET_S = 0.3
HEAVY = (
    "matplotlib",
    "moderngl",
    "glcontext",
    "glfw",
    "PIL",
    "imageio",
    "zmq",
    "mcap",
    "tqdm",
    "gemmi",
    "numpy",
)
COMMANDS = {
    "python -c pass": ["-c", "pass"],
    "python -c 'import numpy'": ["-c", "import numpy"],
    "sasprobe --help": ["-m", "sasprobe", "--help"],
    "sasprobe info": ["-m", "sasprobe", "info"],
    "sasprobe render --help": ["-m", "sasprobe", "render", "--help"],
}
_IMPORTED = (
    "import runpy, sys, json\n"
    "sys.argv = ['sasprobe'] + sys.argv[1:]\n"
    "try:\n    runpy.run_module('sasprobe', run_name='__main__')\n"
    "except SystemExit:\n    pass\n"
    f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({list(HEAVY)!r}))),"
    " file=sys.stderr)\n"
)


def _wall(args: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True
    )
    return time.perf_counter() - t0


def imported(argv: list[str]) -> list[str]:
    """The libraries of HEAVY that `sasprobe ARGV` has loaded by the time it exits."""
    r = subprocess.run(
        [sys.executable, "-c", _IMPORTED, *argv], capture_output=True, text=True, check=True
    )
    return json.loads(r.stderr.strip().splitlines()[-1])


def run(ctx: BenchContext) -> BenchResult:
    repeats = 1 if ctx.smoke else 5 if ctx.quick else 15
    times: dict[str, list[float]] = {label: [] for label in COMMANDS}
    for args in COMMANDS.values():
        if not ctx.smoke:
            _wall(args)  # warm the file cache
    for _ in range(repeats):  # round robin: a change in the machine's load hits every command alike
        for label, args in COMMANDS.items():
            times[label].append(_wall(args))
    rows = []
    for label, args in COMMANDS.items():
        row = {
            "command": label,
            "median_s": statistics.median(times[label]),
            "min_s": min(times[label]),
        }
        if args[:2] == ["-m", "sasprobe"]:
            row["imports"] = imported(args[2:])
        rows.append(row)
    by = {r["command"]: r for r in rows}
    floor = by["python -c pass"]["median_s"]
    help_s = by["sasprobe --help"]["median_s"]
    lines = [
        "| command | median | min | loads (of " + ", ".join(HEAVY) + ") |",
        "|---|---:|---:|---|",
    ]
    for r in rows:
        lines.append(
            f"| `{r['command']}` | {r['median_s'] * 1e3:.0f} ms | {r['min_s'] * 1e3:.0f} ms | "
            f"{', '.join(r.get('imports', [])) or '-'} |"
        )
    lines.append("")
    lines.append(
        f"`sasprobe --help`: {help_s * 1e3:.0f} ms, {help_s / floor:.1f}x a bare interpreter "
        f"(target {HELP_TARGET_S * 1e3:.0f} ms: {'met' if help_s <= HELP_TARGET_S else 'missed'}); "
        f"medians of {repeats} fresh processes."
    )
    return BenchResult(
        name="startup",
        data={
            "rows": rows,
            "repeats": repeats,
            "help_target_s": HELP_TARGET_S,
            "help_over_python": help_s / floor,
        },
        markdown="\n".join(lines),
    )
