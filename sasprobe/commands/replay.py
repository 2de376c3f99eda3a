"""`sasprobe replay FILE`: inspect, verify or recover a recorded session."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="summarise a recording; --verify recomputes its forces; --recover repairs it")
    p.add_argument("file", type=Path, help="an MCAP recording (sasprobe daemon --record)")
    p.add_argument("--verify", action="store_true",
                   help="recompute every force from the recorded inputs and report the largest difference")
    p.add_argument("--recover", type=Path, metavar="OUT",
                   help="write the readable part of a cut recording (daemon killed) as a finished file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.daemon.recording import recover, summarize

    result: dict = {}
    if args.recover is not None:
        result["recovered"] = recover(args.file, args.recover).as_dict()
    summary = summarize(args.file)
    result["summary"] = summary.as_dict()
    status = 0
    if args.verify:
        from sasprobe.daemon.verify import verify_recording
        from sasprobe.progress import progress_bar

        bar = progress_bar(summary.ticks, desc="verify", unit="tick")
        try:
            report = verify_recording(args.file, progress=bar.update)
        finally:
            bar.close()
        result["verify"] = report.as_dict()
        status = 0 if report.ok else 1
    if args.json:
        print(json.dumps(result))
        return status
    s = summary
    print(f"{s.path}: {'finished' if s.finished else 'cut short (daemon killed), readable up to its last flush'}, "
          f"{s.duration_s:.2f} s, {s.ticks} ticks, {s.seq_gaps} missing, structure(s) {', '.join(s.structures)}")
    print("  messages " + ", ".join(f"{k} {v}" for k, v in sorted(s.counts.items())))
    if "recovered" in result:
        print(f"  recovered {result['recovered']['ticks']} ticks into {args.recover}")
    if args.verify:
        r = result["verify"]
        print(f"  verify   {r['ticks']} ticks recomputed, {r['events_applied']} control changes applied: "
              f"max |force difference| {r['max_force_diff_n']:.3g} N over {r['ticks_with_force_diff']} ticks, "
              f"{r['flag_mismatches']} flag mismatches -> {'OK' if r['ok'] else 'DIFFERENT'}")
        if r["missing_ticks"]:
            print(f"  note     {r['missing_ticks']} ticks were dropped while recording; forces after a gap can differ")
    return status
