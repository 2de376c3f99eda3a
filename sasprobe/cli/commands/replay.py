"""`sasprobe replay FILE`: inspect, verify, recover or render a recorded session."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from sasprobe.common.errors import UserError

HELP = (
    "summarise a recording; --verify recomputes its forces; --recover repairs it; "
    "--video renders it; --html makes it one web page"
)


def register(sub: argparse._SubParsersAction) -> None:
    from sasprobe.cli.argtypes import positive_float, probe_radius, size_type
    from sasprobe.render.app import RenderOptions

    video = RenderOptions()  # a replay's video is drawn with `sasprobe render`'s defaults
    size = f"{video.size[0]}x{video.size[1]}"

    p = sub.add_parser("replay", help=HELP)
    p.add_argument("file", type=Path, help="an MCAP recording (sasprobe daemon --record)")
    p.add_argument(
        "--verify",
        action="store_true",
        help="recompute every force from the recorded inputs and report the largest difference",
    )
    p.add_argument(
        "--recover",
        type=Path,
        metavar="OUT",
        help="write the readable part of a cut recording (daemon killed) as a finished file",
    )
    p.add_argument(
        "--video",
        type=Path,
        metavar="OUT.mp4",
        help="render the session to a video at its recorded timing (headless)",
    )
    p.add_argument(
        "--html",
        type=Path,
        metavar="OUT.html",
        help="the session as one self-contained web page that plays offline in any browser "
        "(structure, poses, marks and the findings' summary inside)",
    )
    p.add_argument(
        "--fps",
        type=positive_float,
        default=video.fps,
        help=f"video frame rate (default {video.fps:g})",
    )
    p.add_argument(
        "--size", type=size_type, default=size, metavar="WxH", help=f"video size (default {size})"
    )
    p.add_argument(
        "--findings",
        type=Path,
        metavar="DIR",
        help="what the session found: path, touched residues, marks, bottleneck; a chart, "
        "PDB/mmCIF, PyMOL and ChimeraX files and findings.json into DIR",
    )
    p.add_argument(
        "--probe-radius",
        type=probe_radius,
        default=None,
        metavar="ANGSTROM",
        help="--findings: the probe whose passage the verdict is about (default: the session's)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sasprobe.protocol.recording import recover, summarize

    result: dict = {}
    if args.probe_radius is not None and args.findings is None:
        raise UserError("--probe-radius goes with --findings DIR")
    if args.findings is not None and args.findings.exists() and not args.findings.is_dir():
        raise UserError(f"--findings {args.findings}: exists and is not a folder")
    if args.video is not None:
        from sasprobe.render.output import VIDEO_SUFFIXES

        if args.video.suffix.lower() not in VIDEO_SUFFIXES:
            raise UserError(
                f"--video {args.video}: expected a video file ({', '.join(VIDEO_SUFFIXES)})"
            )
        if not args.video.resolve().parent.is_dir():
            raise UserError(f"--video {args.video}: folder {args.video.parent} does not exist")
    if args.html is not None and not args.html.resolve().parent.is_dir():
        raise UserError(f"--html {args.html}: folder {args.html.parent} does not exist")
    if args.recover is not None:
        with _step(f"recover {args.file.name}"):
            result["recovered"] = recover(args.file, args.recover).as_dict()
    with _step(f"read {args.file.name}"):
        summary = summarize(args.file)
    result["summary"] = summary.as_dict()
    status = 0
    if args.verify:
        from sasprobe.common.progress import progress_bar
        from sasprobe.daemon.recording.verify import verify_recording

        # it counts ticks once the recording is read; until then it shows the wait
        bar = progress_bar(summary.ticks, desc="verify", unit="tick")
        try:
            report = verify_recording(args.file, progress=bar.update)
        finally:
            bar.close()
        result["verify"] = report.as_dict()
        status = 0 if report.ok else 1
    if args.video is not None:
        from sasprobe.common.progress import progress_bar
        from sasprobe.protocol.playback import frame_count, pose_time_range
        from sasprobe.render.playback import render_recording

        with _step(f"video: time line of {args.file.name}"):
            time_range = pose_time_range(args.file)
        bar = progress_bar(
            frame_count(time_range, args.fps) if time_range else 0, desc="video", unit="frame"
        )
        try:
            result["video"] = render_recording(
                args.file, args.video, args.fps, args.size, progress=bar.update
            )
        finally:
            bar.close()
    found = None
    if args.findings is not None:
        from sasprobe.daemon.findings import write_findings

        found = write_findings(args.file, args.findings, args.probe_radius, ticks=summary.ticks)
        result["findings"] = {
            k: found[k] for k in ("files", "bottleneck", "verdict", "session", "notes")
        }
    if args.html is not None:
        result["html"] = write_html(args.file, args.html, found, args.probe_radius)
    if args.json:
        print(json.dumps(result))
        return status
    s = summary
    ending = (
        "finished" if s.finished else "cut short (daemon killed), readable up to its last flush"
    )
    print(
        f"{s.path}: {ending}, format {s.format}, {s.duration_s:.2f} s, {s.ticks} ticks, "
        f"{s.seq_gaps} missing, structure(s) {', '.join(s.structures)}"
    )
    print("  messages " + ", ".join(f"{k} {v}" for k, v in sorted(s.counts.items())))
    if "recovered" in result:
        print(f"  recovered {result['recovered']['ticks']} ticks into {args.recover}")
    if args.verify:
        r = result["verify"]
        print(verify_line(r))
        if r["missing_ticks"]:
            print(
                f"  note     {r['missing_ticks']} ticks were dropped while recording; forces "
                "after a gap can differ"
            )
    if args.findings is not None:
        from sasprobe.daemon.findings import summary_lines

        print("\n".join(summary_lines(found)))
        print(f"  files      {args.findings}/: {', '.join(found['files'].values())}")
    if args.html is not None:
        h = result["html"]
        print(f"  html     {h['html']}: {h['bytes'] / 1e6:.2f} MB, {h['frames']} frames")
    if args.video is not None:
        v = result["video"]
        print(
            f"  video    {v['video']}: {v['frames']} frames at {v['fps']:g} fps, "
            f"{v['size'][0]}x{v['size'][1]} ({v['duration_s']:.2f} s recorded)"
        )
    return status


def write_html(path: Path, out: Path, found: dict | None, probe_radius: float | None) -> dict:
    """The session as one web page (web/export.py), with the findings' summary."""
    from sasprobe.common.progress import progress_bar
    from sasprobe.daemon.findings import analyse, summary_lines
    from sasprobe.web.export import frames_to_write, session_html

    if found is None:
        from sasprobe.daemon.findings.session import read_track

        found = analyse(read_track(path), probe_radius).found
    frames = frames_to_write(path)
    bar = progress_bar(frames, desc="html", unit="frame")
    try:
        html = session_html(path, summary_lines(found), progress=bar.update)
    finally:
        bar.close()
    data = html.encode()
    try:
        out.write_bytes(data)
    except OSError as exc:
        raise UserError(f"--html {out}: cannot write ({exc.strerror or exc})") from None
    return {"html": str(out), "bytes": len(data), "frames": frames}


def _step(desc: str):
    """A replay step that shows it is working (reading a long recording takes a while)."""
    from contextlib import closing

    from sasprobe.common.progress import working

    return closing(working(desc))


def verify_line(r: dict) -> str:
    """The verify report in one line: how many ticks differ, and by how much at most."""
    if r["ticks_with_force_diff"]:
        forces = (
            f"max |force difference| {r['max_force_diff_n']:.3g} N on "
            f"{r['ticks_with_force_diff']} of {r['ticks']} ticks "
            f"(the first at tick {r['first_diff_seq']})"
        )
    else:
        forces = f"every force as recorded (max |force difference| 0 N on all {r['ticks']} ticks)"
    return (
        f"  verify   {r['ticks']} ticks recomputed, {r['events_applied']} control changes "
        f"applied: {forces}, {r['flag_mismatches']} flag mismatches -> "
        + ("OK" if r["ok"] else "DIFFERENT")
    )
