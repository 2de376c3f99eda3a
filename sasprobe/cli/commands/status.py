"""`sasprobe status`: ask a running daemon how it is doing (control channel)."""

from __future__ import annotations

import argparse
import json

HELP = "rate, jitter, overruns, subscribers and recording of a running daemon"


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.cli.daemon_client import add_daemon_options

    p = sub.add_parser("status", help=HELP)
    add_daemon_options(p)
    p.add_argument(
        "--timeout", type=float, default=2.0, metavar="S", help="seconds to wait for the reply"
    )
    p.add_argument("--json", action="store_true", help="print the daemon's status reply as JSON")
    p.set_defaults(func=run)


def _us(value) -> str:
    return "-" if value is None else f"{value:.0f} µs"


def run(args: argparse.Namespace) -> int:
    from sasprobe.cli.daemon_client import connect

    with connect(args, timeout_s=args.timeout) as client:
        status = client.status()
    if args.json:
        print(json.dumps(status))
        return 0
    loop, dev, pub, rec = status["loop"], status["device"], status["publisher"], status["recording"]
    err, recent = loop["period_error_us"], loop["recent"]
    target = loop.get("target_rate_hz")
    print(
        f"sasprobe daemon {status['daemon_version']} (pid {status['pid']}), up "
        f"{status['uptime_s']:.0f} s"
    )
    print(f"  structure   {status['structure']['name']} ({status['structure']['n_atoms']} atoms)")
    print(
        f"  device      {dev['model']} [{dev['kind']}]  "
        + (
            f"FAULT: {dev['last_fault']}"
            if dev["faulted"]
            else f"ok ({dev['faults']} faults so far)"
        )
    )
    rate = recent["rate_hz"]
    print(
        f"  rate        {rate:.1f} Hz over the last {recent['ticks']} ticks"
        if rate
        else "  rate        -",
        f"(target {target:g} Hz)" if target else "(free-running)",
    )
    print(
        f"  jitter      period error p50 {_us(err['p50'])}, p99 {_us(err['p99'])}, max "
        f"{_us(err['max'])} over {loop['window_s']:.0f} s; last second p99 "
        f"{_us(recent['period_error_p99_us'])}"
    )
    print(
        f"  overruns    {loop['total']['overruns']} ({loop['total']['missed_deadlines']} "
        f"deadlines missed) in {loop['total']['ticks']} ticks; loop CPU {loop['cpu_percent']:.0f} "
        f"%, {'real-time' if loop.get('realtime') else 'normal'} scheduling"
    )
    stalls = loop.get("stalls") or {}
    if stalls.get("stalls"):
        zero = stalls["worst_zero_after_ms"]
        print(
            f"  stalls      {stalls['stalls']} (longest {stalls['longest_ms']:.1f} ms); the "
            "watchdog zeroed the force "
            + ("-" if zero is None else f"at worst {zero:.1f} ms")
            + " after the last tick"
        )
    print(
        f"  publisher   {', '.join(pub['endpoints'])}: {pub['subscribers']} subscriber(s), "
        f"{pub['poses_sent']} poses sent"
    )
    if rec is None:
        print("  recording   off")
    else:
        print(
            f"  recording   {rec['path']}: {rec['messages']} "
            f"messages, {rec['bytes'] / 1e6:.1f} MB, "
            f"{rec['dropped']} dropped" + (f", FAILED: {rec['error']}" if rec.get("error") else "")
        )
    job = status.get("findings")
    if job is not None:
        outcome = {
            "running": "running",
            "failed": f"FAILED: {job['error']}",
            "done": f"done: {(job.get('result') or {}).get('verdict', {}).get('verdict', '')}",
        }[job["state"]]
        print(f"  findings    {job['dir']}: {outcome}")
    return 0
