"""`sasprobe bench [--quick|--smoke] [--only NAMES] [--json] [--out DIR] [--page FILE] [NAME]`:
speed and accuracy figures.

Without a name every benchmark of the usual set runs (the long-session ones, `replay` and
`soak`, run by name only and write their own part of the page). One that cannot run here
(without the reference structures or OpenGL, say) is listed as skipped with its reason;
one that fails is one line on stderr and in the report, the others still run, and the
exit status is 1. With --out, report.md and report.json are written beside each benchmark's JSON and
charts. --page writes the run into the benchmark page (docs/benchmarks.md,
sasprobe/cli/bench/report.py). `sasprobe bench --gpu-quick [--gpu-size WxH]` runs only the
short GPU check (sasprobe/cli/bench/gpu_quick.py).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import traceback
from pathlib import Path

from sasprobe.cli import bench
from sasprobe.cli.argtypes import size_type
from sasprobe.common.errors import UserError

HELP = "run benchmarks (speed and accuracy), write JSON, charts, report.md and the benchmark page"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help=HELP)
    _common(p)
    p.add_argument(
        "--only",
        metavar="NAMES",
        help=f"comma-separated benchmarks to run (default all: {', '.join(bench.available())})",
    )
    p.add_argument(
        "--gpu-quick",
        action="store_true",
        help="only the short GPU check: 1080p frame times of 1CRN, 1TII, 1AON, 6ZU5 with a cube "
        "(unlit, default lighting, session frames) and atlas bakes",
    )
    p.add_argument(
        "--gpu-size",
        type=size_type,
        default=None,
        metavar="WxH",
        help="frame size of --gpu-quick (default 1920x1080)",
    )
    names = p.add_subparsers(dest="bench_name", metavar="NAME")
    for name in bench.available() + bench.on_their_own():
        module = bench.load(name)
        q = names.add_parser(name, help=module.TITLE)
        _common(q, suppress=True)
        if hasattr(module, "add_arguments"):
            module.add_arguments(q)
    p.set_defaults(func=run)


def _common(p: argparse.ArgumentParser, suppress: bool = False) -> None:
    # Sub-benchmarks repeat the options so `bench grid --quick` and `bench --quick grid` both work.
    flag = argparse.SUPPRESS if suppress else False
    value = argparse.SUPPRESS if suppress else None
    p.add_argument(
        "--quick",
        action="store_true",
        default=flag,
        help="fewer repeats and structures (a few minutes in all)",
    )
    p.add_argument(
        "--smoke",
        action="store_true",
        default=flag,
        help="every code path once at its smallest size "
        "(seconds; the figures only show that it runs)",
    )
    p.add_argument(
        "--json", action="store_true", default=flag, help="print the figures as one JSON object"
    )
    p.add_argument(
        "--out", type=Path, default=value, help="write JSON, PNG charts and report.md here"
    )
    p.add_argument(
        "--page",
        type=Path,
        default=value,
        metavar="FILE",
        help="write this run's part of the benchmark page FILE (docs/benchmarks.md; charts in the "
        "folder beside it named after it), keeping the page's other part",
    )


def run(args: argparse.Namespace) -> int:
    if args.gpu_quick:
        return _gpu_quick(args)
    from sasprobe.cli.bench.machine import describe
    from sasprobe.cli.bench.report import now

    names = [args.bench_name] if args.bench_name else _selected(getattr(args, "only", None))
    if (
        args.page is not None
        and args.bench_name not in bench.ON_THEIR_OWN
        and names != bench.available()
    ):  # the part's run line, wall times and charts are one run's: a few would drop the rest
        raise UserError(
            f"--page {args.page}: its 'All benchmarks' part is one run of them all; run "
            "`sasprobe bench --page FILE` (no NAME, no --only), or give --out DIR"
        )
    mode = _mode(args)
    with tempfile.TemporaryDirectory(prefix="sasprobe-bench-") as scratch:
        # Charts are drawn only where they go: --out, or for --page a folder of their own.
        charts_dir = args.out if args.out is not None or args.page is None else Path(scratch)
        ctx = bench.BenchContext(quick=mode != "full", smoke=mode == "smoke", out_dir=charts_dir)
        machine = describe(with_gl=True)  # the GL renderer string belongs in every report
        date = now()
        results, skipped, failed = [], {}, {}
        t_start = time.perf_counter()
        for name in names:
            module = bench.load(name)
            t0 = time.perf_counter()
            try:
                result = module.run(ctx, args) if _takes_args(module) else module.run(ctx)
            except UserError as exc:
                if args.bench_name:  # the one asked for: its error is the answer
                    raise
                skipped[name] = str(exc)
                print(
                    f"sasprobe: warning: bench {name} skipped: {exc}", file=sys.stderr, flush=True
                )
                continue
            except (
                Exception
            ) as exc:  # a failed measurement: one line, and the other benchmarks still run
                failed[name] = _failure(exc)
                print(
                    f"sasprobe: error: bench {name} failed: "
                    f"{failed[name]}{_keep_traceback(name, exc, args.out)}",
                    file=sys.stderr,
                    flush=True,
                )
                continue
            result.data["wall_seconds"] = time.perf_counter() - t0
            results.append(result)
            if not args.json:
                print(f"## {module.TITLE}\n\n{result.markdown}\n", flush=True)
        if not results and not failed:
            raise UserError(
                "no benchmark could run: " + "; ".join(f"{n}: {why}" for n, why in skipped.items())
            )
        total_s = time.perf_counter() - t_start
        payload = {
            "machine": machine,
            "date": date,
            "mode": mode,
            "wall_seconds": total_s,
            "skipped": skipped,
            "failed": failed,
            "benchmarks": {r.name: r.data for r in results},
        }
        _write(args, payload, results)
    if args.json:
        print(json.dumps(payload))
    if failed:
        print(
            f"sasprobe: error: {len(failed)} benchmark(s) failed: {', '.join(failed)}",
            file=sys.stderr,
        )
        return 1
    return 0


def _mode(args: argparse.Namespace) -> str:
    return "smoke" if getattr(args, "smoke", False) else "quick" if args.quick else "full"


def _failure(exc: Exception) -> str:
    """One line for a benchmark that raised: the error and where in sasprobe it was raised."""
    ours = [
        (f.f_globals["__name__"], line)
        for f, line in traceback.walk_tb(exc.__traceback__)
        if str(f.f_globals.get("__name__", "")).startswith("sasprobe.")
    ]
    where = f" at {ours[-1][0]}:{ours[-1][1]}" if ours else ""
    message = (str(exc).strip().splitlines() or [""])[0][:300]
    return f"{type(exc).__name__}{': ' + message if message else ''}{where}"


def _keep_traceback(name: str, exc: Exception, out: Path | None) -> str:
    """With --out, the whole traceback goes to OUT/NAME.error.txt; where, for the stderr line."""
    if out is None:
        return ""
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.error.txt").write_text("".join(traceback.format_exception(exc)))
    return f" (traceback in {out / f'{name}.error.txt'})"


def _write(args: argparse.Namespace, payload: dict, results: list[bench.BenchResult]) -> None:
    from sasprobe.cli.bench import report

    machine, mode, date = payload["machine"], payload["mode"], payload["date"]
    tables = (payload["skipped"], payload["failed"], payload["wall_seconds"])
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        for r in results:
            (args.out / f"{r.name}.json").write_text(
                json.dumps({"machine": machine, **r.data}, indent=1)
            )
        (args.out / "report.json").write_text(json.dumps(payload, indent=1))
        (args.out / "report.md").write_text(
            report.report_markdown(machine, results, mode, date, *tables)
        )
        print(f"wrote {args.out / 'report.md'}", file=sys.stderr)
    if args.page is not None:
        prefix = f"{report.charts_folder(args.page).name}/"
        part = args.bench_name if args.bench_name in bench.ON_THEIR_OWN else "all"
        body = report.all_part(
            machine, results, mode, date, *tables, chart_prefix=prefix, part=part
        )
        report.write_page(args.page, part, body, [c for r in results for c in r.charts])
        print(f"wrote {args.page}", file=sys.stderr)


def _gpu_quick(args: argparse.Namespace) -> int:
    from sasprobe.cli.bench import gpu_quick, report
    from sasprobe.cli.bench.machine import describe, markdown

    if args.bench_name or args.only:
        raise UserError("--gpu-quick runs on its own (no benchmark name, no --only)")
    mode = _mode(args)
    machine = describe(with_gl=True)
    date = report.now()
    print(
        f"sasprobe: GPU check on {machine.get('gl_renderer') or 'an unknown GL renderer'}",
        file=sys.stderr,
        flush=True,
    )
    try:
        plan = gpu_quick.smoke_plan() if mode == "smoke" else {}
        size = args.gpu_size or (
            gpu_quick.SMOKE_SIZE if mode == "smoke" else gpu_quick.DEFAULT_SIZE
        )
        result = gpu_quick.run(
            size,
            **plan,
            progress=lambda sid: print(f"sasprobe: {sid} done", file=sys.stderr, flush=True),
        )
    except UserError:
        raise
    except Exception as exc:  # a failed measurement: one line
        print(
            "sasprobe: error: bench --gpu-quick failed: "
            f"{_failure(exc)}{_keep_traceback('gpu_quick', exc, args.out)}",
            file=sys.stderr,
        )
        return 1
    text = gpu_quick.markdown(result, machine.get("gpu"))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "gpu_quick.json").write_text(
            json.dumps({"machine": machine, "date": date, **result}, indent=1)
        )
        (args.out / "gpu_quick.md").write_text(
            f"# {gpu_quick.TITLE}\n\n{markdown(machine)}\n\n{text}\n"
        )
    if args.page is not None:
        report.write_page(
            args.page, "gpu-quick", report.gpu_part(machine, mode, date, gpu_quick.TITLE, text)
        )
        print(f"wrote {args.page}", file=sys.stderr)
    print(
        json.dumps({"machine": machine, "date": date, **result})
        if args.json
        else f"## {gpu_quick.TITLE}\n\n{text}"
    )
    return 0


def _selected(only: str | None) -> list[str]:
    available = bench.available()
    if not only:
        return available
    names = [n.strip() for n in only.split(",") if n.strip()]
    unknown = [n for n in names if n not in available]
    if unknown or not names:
        raise UserError(
            f"--only {only}: unknown benchmark(s) {', '.join(unknown) or '(none given)'} "
            f"(available: {', '.join(available)})"
        )
    return [n for n in available if n in names]  # in the usual order


def _takes_args(module) -> bool:
    import inspect

    return len(inspect.signature(module.run).parameters) > 1
