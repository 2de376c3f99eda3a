"""What `sasprobe bench` writes besides each benchmark's JSON: report.md for one run, and
the benchmark page (docs/benchmarks.md) regenerated from the latest runs.

The page holds one part per kind of run, each written whole by that run: `all` (the
benchmarks, `sasprobe bench --page PAGE`), one per benchmark run by name (`sasprobe bench
rates --page PAGE`, on a machine chosen for it; `replay` and `soak`, long recordings and
sessions) and `gpu-quick` (`sasprobe bench --gpu-quick --page PAGE`, on a machine with a
GPU). Writing one part keeps the others as they stand, since they usually run at different
times or on different machines; each part names its own machine, date and code. Charts are
copied into a folder beside the page named after it (docs/benchmarks/) and linked
relatively; a chart there that no part links to is removed.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from datetime import datetime, timezone
from pathlib import Path

from sasprobe.cli.bench.machine import markdown as machine_markdown

PARTS = {  # in the page's order
    "all": "All benchmarks",
    "rates": "Loop rates",
    "replay": "Long recordings",
    "soak": "Long sessions",
    "gpu-quick": "GPU check",
}
MODES = {
    "full": "full size",
    "quick": "--quick: fewer repeats and structures",
    "smoke": "--smoke: every code path at its smallest size; the figures only show that it runs",
}
HEADER = """# Benchmarks

This page is written by `sasprobe bench --page docs/benchmarks.md` (every benchmark at full
size), by `sasprobe bench rates --page docs/benchmarks.md` (the haptic loop at 1, 2 and
4 kHz, quiet and beside busy loops), by `sasprobe bench replay --page docs/benchmarks.md` and
`sasprobe bench soak --page docs/benchmarks.md` (long recordings and long sessions) and by
`sasprobe bench --gpu-quick --page docs/benchmarks.md` (the GPU check, on a machine with a
GPU); each part is rewritten whole by its own run, and names the machine, the date and the
code it measured. Times are medians; every ratio compares figures measured in the same run.
`sasprobe bench --quick` (minutes) and `sasprobe bench --smoke` (seconds: each benchmark's
code path at its smallest, to check that it runs) write the same report with
fewer figures; `--out DIR` keeps a run's JSON, charts and report.md apart from this page.
"""


def now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def code_version() -> str:
    """sasprobe's version, and the commit of the checkout it runs from where there is one."""
    from sasprobe import __version__
    from sasprobe.cli.reference_data import REPO_ROOT

    text = f"sasprobe {__version__}"
    if not (REPO_ROOT / ".git").exists():
        return text
    try:
        commit = subprocess.run(
            ["git", "-C", str(REPO_ROOT), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        changed = subprocess.run(
            # the benchmark page and the other docs change no figure
            ["git", "-C", str(REPO_ROOT), "status", "--porcelain", "--untracked-files=no"]
            + ["--", ".", ":(exclude)docs"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        return text
    return f"{text}, commit {commit}{' with local changes' if changed else ''}" if commit else text


def wall_time_table(
    results, skipped: dict[str, str], failed: dict[str, str], total_s: float
) -> list[str]:
    return [
        "| benchmark | wall time (s) |",
        "|---|---:|",
        *[f"| {r.name} | {r.data['wall_seconds']:.1f} |" for r in results],
        *[f"| {name} | skipped: {why} |" for name, why in skipped.items()],
        *[f"| {name} | failed: {why} |" for name, why in failed.items()],
        f"| **all** | **{total_s:.1f}** |",
    ]


def sections(results, level: int, chart_prefix: str = "") -> list[str]:
    """One section per benchmark, its title at heading `level` and its own headings below
    it, then its charts (linked as chart_prefix + file name)."""
    from sasprobe.cli import bench

    parts = []
    for r in results:
        parts += [
            "",
            f"{'#' * level} {bench.load(r.name).TITLE}",
            "",
            demote(r.markdown, level - 2),
        ]
        parts += [f"\n![{c.stem}]({chart_prefix}{c.name})" for c in r.charts]
    return parts


def demote(text: str, by: int) -> str:
    """Markdown with its headings `by` levels lower."""
    return (
        re.sub(r"^(#+) ", lambda m: "#" * (len(m.group(1)) + by) + " ", text, flags=re.M)
        if by > 0
        else text
    )


def report_markdown(
    machine: dict,
    results,
    mode: str,
    date: str,
    skipped: dict[str, str],
    failed: dict[str, str],
    total_s: float,
) -> str:
    """report.md of one run."""
    parts = [
        "# sasprobe benchmark report",
        "",
        f"Run of {date} ({MODES[mode]}), {code_version()}. "
        "Times are medians; ratios come from the same run.",
        "",
        machine_markdown(machine),
        "",
        *wall_time_table(results, skipped, failed, total_s),
        *sections(results, 2),
    ]
    return "\n".join(parts) + "\n"


def all_part(
    machine: dict,
    results,
    mode: str,
    date: str,
    skipped: dict[str, str],
    failed: dict[str, str],
    total_s: float,
    chart_prefix: str,
    part: str = "all",
) -> str:
    return "\n".join(
        [
            f"## {PARTS[part]}",
            "",
            f"Run of {date} ({MODES[mode]}), {code_version()}; {total_s:.0f} s in all.",
            "",
            machine_markdown(machine),
            "",
            *wall_time_table(results, skipped, failed, total_s),
            *sections(results, 3, chart_prefix),
        ]
    )


def gpu_part(machine: dict, mode: str, date: str, title: str, text: str) -> str:
    return "\n".join(
        [
            f"## {PARTS['gpu-quick']}",
            "",
            f"{title}. Run of {date} ({MODES[mode]}), {code_version()}.",
            "",
            machine_markdown(machine),
            "",
            demote(text, 1),
        ]
    )


def charts_folder(page: Path) -> Path:
    return page.with_suffix("")


def write_page(page: Path, part: str, body: str, charts=()) -> None:
    """Put `body` as the page's `part` (copying `charts` beside it), keeping the other parts."""
    kept = _parts(page.read_text()) if page.is_file() else {}
    kept[part] = body
    folder = charts_folder(page)
    if charts:
        folder.mkdir(parents=True, exist_ok=True)
        for chart in charts:
            if chart.resolve() != (folder / chart.name).resolve():
                shutil.copyfile(chart, folder / chart.name)
    blocks = [HEADER]
    for name in PARTS:
        how = {"all": "", "gpu-quick": "--gpu-quick "}.get(name, f"{name} ")
        text = kept.get(name) or (
            f"## {PARTS[name]}\n\nNot measured yet: `sasprobe bench {how}--page "
            "docs/benchmarks.md` writes this part."
        )
        blocks.append(
            f"<!-- sasprobe bench: {name} -->\n{text.strip()}\n<!-- sasprobe bench: end {name} -->"
        )
    page.parent.mkdir(parents=True, exist_ok=True)
    page.write_text("\n\n".join(blocks) + "\n")
    if folder.is_dir():  # charts of earlier runs that no part shows any more
        linked = set(re.findall(rf"\]\({re.escape(folder.name)}/([^)/]+)\)", page.read_text()))
        for stale in folder.glob("*.png"):
            if stale.name not in linked:
                stale.unlink()


def _parts(text: str) -> dict[str, str]:
    found = re.findall(
        r"<!-- sasprobe bench: ([\w-]+) -->\n(.*?)\n<!-- sasprobe bench: end \1 -->", text, re.S
    )
    return {name: body for name, body in found if name in PARTS}
