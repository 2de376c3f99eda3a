"""Every benchmark runs, and `sasprobe bench` reports it: `sasprobe bench --smoke` runs each
one's code path at its smallest size on 1CRN alone (a private MANIFEST), and every figure it
reports must be finite, with the keys each benchmark promises and its times positive; the
run writes report.md and the benchmark page (docs/benchmarks.md's writer), whose GPU part
another run writes and each keeps. A benchmark that fails is one line, and the others still
report."""

from __future__ import annotations

import json
import math
import os
import re
import shutil

import pytest

from sasprobe.cli import bench
from sasprobe.cli.bench import report
from tests.conftest import in_ci, run_cli, skip_or_fail
from tests.support.reference_data import small_reference_data

SMOKE_TIMEOUT_S = 900  # about a minute on an idle 2-core machine; several on a shared one
pytestmark = pytest.mark.timeout(SMOKE_TIMEOUT_S + 300)  # the first test waits for the whole run
GPU_PART_BEFORE = "## GPU check\n\nfigures of another machine's run"


@pytest.fixture(scope="module")
def smoke(reference_entries, gl, tmp_path_factory):
    """One `sasprobe bench --smoke` run of every benchmark on 1CRN, into a page that already
    holds a GPU part."""
    folder = tmp_path_factory.mktemp("smoke")
    data = small_reference_data(reference_entries, folder / "pdb", ids=("1crn",))
    page = folder / "docs" / "benchmarks.md"
    report.write_page(page, "gpu-quick", GPU_PART_BEFORE)
    out = folder / "out"
    result = run_cli(
        "bench",
        "--smoke",
        "--json",
        "--out",
        str(out),
        "--page",
        str(page),
        env=dict(os.environ, SASPROBE_DATA=str(data)),
        timeout=SMOKE_TIMEOUT_S,
    )
    return {
        "result": result,
        "summary": json.loads(result.stdout),
        "out": out,
        "page": page,
        "data": data,
    }


def test_the_run_ends_well(smoke):
    result = smoke["result"]
    assert "Traceback" not in result.stderr, result.stderr
    assert result.returncode == 0, result.stderr


def _numbers(tree, path=""):
    """(path, value) of every number in a JSON tree."""
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield from _numbers(value, f"{path}.{key}")
    elif isinstance(tree, list):
        for i, value in enumerate(tree):
            yield from _numbers(value, f"{path}[{i}]")
    elif isinstance(tree, (int, float)) and not isinstance(tree, bool):
        yield path, tree


# Per benchmark: the keys its figures hold, and the times (or rates) that must be positive.
EXPECTED = {
    "startup": (
        {"rows", "repeats", "help_over_python"},
        lambda d: [r["median_s"] for r in d["rows"]] + [d["help_over_python"]],
    ),
    "grid": (
        {"structures", "embedded_load_s"},
        lambda d: [s[k] for s in d["structures"] for k in ("load_s", "grid_s", "query_us")],
    ),
    "sas": (
        {"structures"},
        lambda d: [s[k] for s in d["structures"] for k in ("ours_s", "freesasa_s")],
    ),
    "haptics": (
        {"rows", "stability", "ticks_per_session"},
        lambda d: [r[k] for r in d["rows"] for k in ("p50_us", "p99_us", "setup_s")],
    ),
    "daemon": (
        {"runs", "devices", "loading"},
        lambda d: (
            [r["loop"]["rate_hz"] for r in d["runs"] + d["devices"]["rows"]]
            + [r["tcp"]["received"] for r in d["runs"]]
            + [d["loading"]["poses"], d["loading"]["loads_of_big"]]
        ),
    ),
    "render": (
        {"modes", "cube", "scaling", "scenarios", "sessions"},
        lambda d: (
            [
                m[k][t]
                for m in d["modes"]
                for k in ("quad", "sprite", "mesh")
                for t in ("frame_s", "atoms_pass_s")
            ]
            + [
                r[k]
                for r in d["sessions"]["rows"]
                for k in ("cpu_ms", "first_frame_s", "connect_frames_1_s")
            ]
            + [r[k] for r in d["scaling"] for k in ("frame_s", "spheres_s")]
            + [d["cube"]["frame_s"], d["cube"]["moving_frame_s"], d["cube"]["small_whole_frame_s"]]
            + [
                row["ms"]
                for key in ("session", "orbit", "cube")
                for s in d["scenarios"][key]
                for row in s["rows"].values()
            ]
        ),
    ),
    "lighting": (
        {
            "ao",
            "ao_scaling",
            "shadow_cells",
            "cube_shadows",
            "probe_light",
            "sun_light",
            "precomputed_bake",
        },
        lambda d: (
            [r["ms"] for r in d["ao"]]
            + [r[k] for r in d["shadow_cells"] for k in ("hard_ms", "soft_ms")]
            + [r["analytic_ms"] for r in d["ao_scaling"]]
            + [r["cube_hard_ms"] for r in d["cube_shadows"]]
            + [d["path_trace_1spp_3_bounces_ms"]]
        ),
    ),
    "web": (
        {"sessions", "bridge_cpu", "pose_gaps", "html"},
        lambda d: (
            [r["fps"] for r in d["sessions"]]
            + [r["poses_sent_per_s"] for r in d["bridge_cpu"] if r["pages"]]
            + [d["html"][k] for k in ("bytes", "build_s", "load_s")]
            + [d["pose_gaps"]["idle"]["poses"], d["pose_gaps"]["with_pages"]["poses"]]
        ),
    ),
}


def without_a_browser() -> str | None:
    """Why the web benchmark cannot run here (no headless Chromium), or None."""
    from sasprobe.cli.browser import find_browser
    from sasprobe.common.errors import UserError

    try:
        find_browser()
    except UserError as exc:
        return str(exc)
    return None


def test_every_benchmark_has_its_checks():
    assert set(EXPECTED) == set(bench.available())


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_benchmark_runs_with_sane_figures(smoke, name):
    summary = smoke["summary"]
    if name == "web" and without_a_browser():
        skip_or_fail(f"no headless browser for bench web: {without_a_browser()}")
    assert name in summary["benchmarks"], (
        f"{name} did not run: {summary['failed'].get(name) or summary['skipped'].get(name)}"
    )
    figures = summary["benchmarks"][name]
    keys, positive = EXPECTED[name]
    assert keys <= set(figures), keys - set(figures)
    for path, value in _numbers(figures):
        assert math.isfinite(value), f"{name}{path} = {value}"
    values = positive(figures)
    assert values and all(v > 0 for v in values), values
    assert figures["wall_seconds"] > 0
    if name == "sas":  # the same spheres as FreeSASA: the areas agree
        assert abs(figures["structures"][0]["total_rel_error"]) < 0.01
    if name == "haptics":
        assert {r["method"] for r in figures["rows"]} == {"proxy", "penalty"}
        stability = figures["stability"]
        assert len(stability["cells"]) == 2 * len(stability["rates_hz"]) * len(
            stability["stiffness_n_per_mm"]
        )


def test_report_names_the_machine_and_every_benchmark(smoke):
    summary, out = smoke["summary"], smoke["out"]
    skipped = set(summary["skipped"]) - ({"web"} if without_a_browser() and not in_ci() else set())
    assert summary["mode"] == "smoke" and not summary["failed"] and not skipped
    machine = summary["machine"]
    assert machine["cpu"] and machine["cores"] >= 1 and machine["gl_renderer"] and machine["python"]
    text = (out / "report.md").read_text()
    assert (
        f"| cpu | {machine['cpu']} |" in text
        and f"| gl_renderer | {machine['gl_renderer']} |" in text
    )
    assert summary["date"] in text
    for name in bench.available():
        assert re.search(rf"^\| {name} \| \d+\.\d \|$", text, re.M), name
        assert f"## {bench.load(name).TITLE}" in text
        assert json.loads((out / f"{name}.json").read_text())["machine"] == machine
    for chart in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        assert (out / chart).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_page_holds_the_run_and_keeps_the_gpu_part(smoke):
    page, summary = smoke["page"], smoke["summary"]
    text = page.read_text()
    assert text.startswith("# Benchmarks\n") and GPU_PART_BEFORE in text
    run = text[
        text.index("<!-- sasprobe bench: all -->") : text.index("<!-- sasprobe bench: end all -->")
    ]
    assert summary["date"] in run and f"| cpu | {summary['machine']['cpu']} |" in run
    for name in bench.available():
        assert f"\n### {bench.load(name).TITLE}\n" in run
    charts = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", run)
    assert charts and all(c.startswith("benchmarks/") for c in charts)  # relative to the page
    for chart in charts:
        assert (page.parent / chart).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The run's only third-level headings are the benchmarks' titles; their own sit below.
    titles = [f"### {bench.load(name).TITLE}" for name in bench.available()]
    assert re.findall(r"^### .*$", run, re.M) == titles


def test_gpu_check_writes_its_part_and_keeps_the_run(smoke, tmp_path):
    page = tmp_path / "benchmarks.md"
    shutil.copyfile(smoke["page"], page)
    shutil.copytree(smoke["page"].with_suffix(""), tmp_path / "benchmarks")
    before = page.read_text()
    run_part = before[before.index("<!-- sasprobe bench: all -->") :]
    run_part = run_part[: run_part.index("<!-- sasprobe bench: end all -->")]
    r = run_cli(
        "bench",
        "--gpu-quick",
        "--smoke",
        "--page",
        str(page),
        env=dict(os.environ, SASPROBE_DATA=str(smoke["data"])),
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    text = page.read_text()
    assert run_part in text and GPU_PART_BEFORE not in text
    gpu = text[text.index("<!-- sasprobe bench: gpu-quick -->") :]
    assert "| cpu |" in gpu and "| 1crn + " in gpu and "| occlusion atlas bake |" in gpu
    assert text.index("sasprobe bench: all") < text.index("sasprobe bench: gpu-quick")
    charts = re.findall(r"\]\(benchmarks/([^)]+)\)", text)
    assert sorted(p.name for p in (tmp_path / "benchmarks").iterdir()) == sorted(charts)


@pytest.mark.filterwarnings("ignore:Data has no positive values")  # the chart of a zero time
def test_a_failed_benchmark_is_one_line_and_the_others_still_report(
    reference_entries, tmp_path, monkeypatch, capsys
):
    from sasprobe.cli.bench import machine, sas
    from sasprobe.cli.main import main

    def zero_time(
        fn, repeats
    ):  # the measurement runs, but its time reads 0: the report's ratio divides by it
        fn()
        return 0.0

    monkeypatch.setattr(sas, "median_time", zero_time)
    monkeypatch.setattr(
        machine, "gl_renderer", lambda: "none"
    )  # no GL context made in the test process
    monkeypatch.setenv(
        "SASPROBE_DATA",
        str(small_reference_data(reference_entries, tmp_path / "pdb", ids=("1crn",))),
    )
    out = tmp_path / "out"
    status = main(["bench", "--quick", "--only", "grid,sas,haptics", "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 1 and "Traceback" not in err
    failed = [line for line in err.splitlines() if "bench sas failed" in line]
    assert (
        len(failed) == 1
        and "ZeroDivisionError" in failed[0]
        and " at sasprobe.cli.bench.sas:" in failed[0]
    )
    assert failed[0].endswith(f"(traceback in {out / 'sas.error.txt'})")
    assert "benchmark(s) failed: sas" in err.splitlines()[-1]
    assert (
        "bench haptics skipped: unknown reference structure" in err
    )  # --quick wants 1CRN, 1TII, 1AON, 6ZU5
    text = (out / "report.md").read_text()
    assert re.search(
        r"^\| sas \| failed: ZeroDivisionError: float division by zero "
        r"at sasprobe\.cli\.bench\.sas:\d+ \|$",
        text,
        re.M,
    )  # no path of this run's folder in a report that may become the page
    assert re.search(r"^\| haptics \| skipped: .*unknown reference structure", text, re.M)
    assert "## Structure loading" in text and json.loads((out / "report.json").read_text())[
        "failed"
    ].keys() == {"sas"}
    assert "Traceback" in (out / "sas.error.txt").read_text()


def test_a_page_is_not_overwritten_by_some_of_the_benchmarks(tmp_path):
    """`bench web --page` or `--only` would replace the whole run's part (its sections and
    charts) with a few: refused in one line before anything runs, the page as it was."""
    page = tmp_path / "benchmarks.md"
    page.write_text("# Benchmarks\n\nkept\n")
    for args in (["web"], ["--only", "grid,sas"]):
        result = run_cli("bench", *args, "--page", str(page))
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1, result.stderr
        assert "is one run of them all" in lines[0]
    assert page.read_text() == "# Benchmarks\n\nkept\n"


def test_unknown_benchmark_name_is_one_line():
    result = run_cli("bench", "--only", "grid,nonsense")
    lines = result.stderr.strip().splitlines()
    assert (
        result.returncode == 2 and len(lines) == 1 and "unknown benchmark(s) nonsense" in lines[0]
    )
