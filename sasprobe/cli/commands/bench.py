"""`sasprobe bench [--quick] [--only NAMES] [--json] [--out DIR] [NAME]`: speed and accuracy figures.

Without a name every available benchmark runs (one that cannot run here, e.g. without
the reference structures or OpenGL, is listed as skipped with its reason) and, with --out,
report.md and report.json are written beside each benchmark's JSON and charts.
`sasprobe bench --gpu-quick [--gpu-size WxH]` runs only the short GPU check
(sasprobe/cli/bench/gpu_quick.py).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from sasprobe.cli import bench
from sasprobe.common.errors import UserError
from sasprobe.cli.argtypes import size_type

HELP = "run benchmarks (speed and accuracy), write JSON, charts and report.md"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help=HELP)
    _common(p)
    p.add_argument("--only", metavar="NAMES", help=f"comma-separated benchmarks to run (default all: "
                                                   f"{', '.join(bench.available())})")
    p.add_argument("--gpu-quick", action="store_true",
                   help="only the short GPU check: 1080p frame times of 1CRN, 1TII, 1AON, 6ZU5 with a cube "
                        "(unlit, default lighting, session frames) and atlas bakes")
    p.add_argument("--gpu-size", type=size_type, default=None, metavar="WxH",
                   help="frame size of --gpu-quick (default 1920x1080)")
    names = p.add_subparsers(dest="bench_name", metavar="NAME")
    for name in bench.available():
        module = bench.load(name)
        q = names.add_parser(name, help=module.TITLE)
        _common(q, suppress=True)
        if hasattr(module, "add_arguments"):
            module.add_arguments(q)
    p.set_defaults(func=run)


def _common(p: argparse.ArgumentParser, suppress: bool = False) -> None:
    # Sub-benchmarks repeat the options so `bench grid --quick` and `bench --quick grid` both work.
    default = argparse.SUPPRESS if suppress else None
    p.add_argument("--quick", action="store_true", default=argparse.SUPPRESS if suppress else False,
                   help="fewer repeats and structures (a few minutes in all)")
    p.add_argument("--json", action="store_true", default=argparse.SUPPRESS if suppress else False,
                   help="print the figures as one JSON object")
    p.add_argument("--out", type=Path, default=default, help="write JSON, PNG charts and report.md here")


def run(args: argparse.Namespace) -> int:
    if args.gpu_quick:
        return _gpu_quick(args)
    from sasprobe.cli.bench.machine import describe

    names = [args.bench_name] if args.bench_name else _selected(getattr(args, "only", None))
    ctx = bench.BenchContext(quick=args.quick, out_dir=args.out)
    machine = describe(with_gl=True)  # the GL renderer string belongs in every report
    results, skipped = [], {}
    t_start = time.perf_counter()
    for name in names:
        t0 = time.perf_counter()
        try:
            result = bench.load(name).run(ctx, args) if _takes_args(name) else bench.load(name).run(ctx)
        except UserError as exc:
            if args.bench_name:  # the one asked for: its error is the answer
                raise
            skipped[name] = str(exc)
            print(f"sasprobe: warning: bench {name} skipped: {exc}", file=sys.stderr, flush=True)
            continue
        result.data["wall_seconds"] = time.perf_counter() - t0
        results.append(result)
        if not args.json:
            print(f"## {bench.load(name).TITLE}\n\n{result.markdown}\n", flush=True)
    if not results:
        raise UserError("no benchmark could run: " + "; ".join(f"{n}: {why}" for n, why in skipped.items()))
    total_s = time.perf_counter() - t_start
    payload = {"machine": machine, "quick": args.quick, "wall_seconds": total_s, "skipped": skipped,
               "benchmarks": {r.name: r.data for r in results}}
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        for r in results:
            (args.out / f"{r.name}.json").write_text(json.dumps({"machine": machine, **r.data}, indent=1))
        (args.out / "report.json").write_text(json.dumps(payload, indent=1))
        (args.out / "report.md").write_text(_report(machine, results, args.quick, skipped, total_s))
        print(f"wrote {args.out / 'report.md'}", file=sys.stderr)
    if args.json:
        print(json.dumps(payload))
    return 0


def _gpu_quick(args: argparse.Namespace) -> int:
    from sasprobe.cli.bench import gpu_quick
    from sasprobe.cli.bench.machine import describe, markdown

    if args.bench_name or args.only:
        raise UserError("--gpu-quick runs on its own (no benchmark name, no --only)")
    machine = describe(with_gl=True)
    print(f"sasprobe: GPU check on {machine.get('gl_renderer') or 'an unknown GL renderer'}", file=sys.stderr, flush=True)
    result = gpu_quick.run(args.gpu_size or gpu_quick.DEFAULT_SIZE,
                           progress=lambda sid: print(f"sasprobe: {sid} done", file=sys.stderr, flush=True))
    text = gpu_quick.markdown(result, machine.get("gpu"))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "gpu_quick.json").write_text(json.dumps({"machine": machine, **result}, indent=1))
        (args.out / "gpu_quick.md").write_text(f"# {gpu_quick.TITLE}\n\n{markdown(machine)}\n\n{text}\n")
    print(json.dumps({"machine": machine, **result}) if args.json else f"## {gpu_quick.TITLE}\n\n{text}")
    return 0


def _selected(only: str | None) -> list[str]:
    available = bench.available()
    if not only:
        return available
    names = [n.strip() for n in only.split(",") if n.strip()]
    unknown = [n for n in names if n not in available]
    if unknown or not names:
        raise UserError(f"--only {only}: unknown benchmark(s) {', '.join(unknown) or '(none given)'} "
                        f"(available: {', '.join(available)})")
    return [n for n in available if n in names]  # in the usual order


def _takes_args(name: str) -> bool:
    import inspect

    return len(inspect.signature(bench.load(name).run).parameters) > 1


def _report(machine: dict, results: list[bench.BenchResult], quick: bool, skipped: dict[str, str],
            total_s: float) -> str:
    from sasprobe.cli.bench.machine import markdown

    parts = [
        "# sasprobe benchmark report",
        "",
        f"Mode: {'quick' if quick else 'full'}. Times are medians; ratios come from the same run.",
        "",
        markdown(machine),
        "",
        "| benchmark | wall time (s) |",
        "|---|---:|",
        *[f"| {r.name} | {r.data['wall_seconds']:.1f} |" for r in results],
        *[f"| {name} | skipped: {why} |" for name, why in skipped.items()],
        f"| **all** | **{total_s:.1f}** |",
    ]
    for r in results:
        parts += ["", f"## {bench.load(r.name).TITLE}", "", r.markdown]
        parts += [f"\n![{c.stem}]({c.name})" for c in r.charts]
    return "\n".join(parts) + "\n"
