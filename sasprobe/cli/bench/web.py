"""`sasprobe bench web`: the browser page's frame rate and latency, the bridge's CPU, the
daemon's pose gaps under many pages, and the HTML export's size and load time.

Every run is a real `sasprobe daemon` (simulated arm, scan script) followed by
`sasprobe web`, and headless Chromium (sasprobe/cli/browser.py: SwiftShader's WebGL2).
- **Sessions**: one page per structure and picture size. Each frame is finished as it is
  drawn (`timeDraws()`: a pixel read back, which makes SwiftShader draw it) and timed: the
  draw time p50 and p95 (last 200 frames) and the frames a second that p50 allows; the
  frames the page showed a second over the window; and the latency from the daemon
  publishing a pose to the bridge hearing the page drew it (p50 and p95 of the page's last
  1000 drawn poses, on the daemon's clock). Beside them, per picture size, the floor: a
  finished frame of one full-screen pass writing one colour on a blank page, the least any
  page that writes every pixel once can cost here. Chromium's unpaced presentation
  (`--disable-frame-rate-limit`) is not used: it counts frames handed to the GPU process,
  not drawn ones, and the backlog they build stalls the page for a minute at a time.
- **Bridge CPU**: the bridge's CPU time over the window with no page, then with 1, 2 and 4
  pages (default pacing, small pictures); per page, the increase divided by the pages.
- **Pose gaps**: the daemon's worst gap between consecutive poses (their publish times)
  idle, and with 10 pages of which one stops reading (its script blocks forever).
- **HTML**: a session of 1AON recorded for a minute, written by `replay --html`; its size
  and the time a page takes to open it and draw its first frame, per minute of session.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from sasprobe.cli.bench import BenchContext, BenchResult
from sasprobe.cli.bench.charts import figure, save
from sasprobe.cli.browser import Browser, WebBridge, find_browser
from sasprobe.cli.children import DaemonChild
from sasprobe.cli.reference_data import reference_structures
from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress

TITLE = "Web page: frame rate, latency, bridge CPU, pose gaps, HTML export"
TARGETS = (
    "the 1AON session page ≥ 60 frames/s at 1280x720 (a finished frame in ≤ 16.7 ms) with "
    "latency p95 ≤ 50 ms; a 60 s "
    "1AON session's HTML ≤ 3 MB; 10 pages with one stalled: the daemon's worst pose gap within "
    "1 ms of its idle figure"
)
READY_S = 120.0
FLOOR_FRAMES = 30
# A canvas filling the window, one triangle over it in one colour, each frame finished by a
# pixel read back as the page's timeDraws() does; the median time of FLOOR_FRAMES frames.
_FLOOR_JS = """
const canvas = document.createElement("canvas");
canvas.width = window.innerWidth;
canvas.height = window.innerHeight;
canvas.style.display = "block";
document.body.style.margin = "0";
document.body.appendChild(canvas);
const gl = canvas.getContext("webgl2", { antialias: false, alpha: false });
const program = gl.createProgram();
for (const [type, text] of [
  [gl.VERTEX_SHADER, `#version 300 es
void main() {
  gl_Position = vec4(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID & 2) * 2 - 1), 0, 1);
}`],
  [gl.FRAGMENT_SHADER, `#version 300 es
precision highp float;
uniform float u_k;
out vec4 o;
void main() { o = vec4(u_k, 0.5, 0.25, 1.0); }`]]) {
  const shader = gl.createShader(type);
  gl.shaderSource(shader, text);
  gl.compileShader(shader);
  gl.attachShader(program, shader);
}
gl.linkProgram(program);
gl.useProgram(program);
gl.bindVertexArray(gl.createVertexArray());
const pixel = new Uint8Array(4);
const times = [];
for (let k = 0; k < arguments[0]; k++) {
  const start = performance.now();
  gl.uniform1f(gl.getUniformLocation(program, "u_k"), (k % 7) / 7);
  gl.drawArrays(gl.TRIANGLES, 0, 3);
  gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
  times.push(performance.now() - start);
}
times.sort((a, b) => a - b);
return [canvas.width, canvas.height, times[times.length >> 1]];
"""
SMALL = (480, 270)  # the pages of the CPU and pose-gap runs


def add_arguments(parser) -> None:
    parser.add_argument(
        "--seconds", type=float, default=None, help="measured window per run (default 10, quick 4)"
    )
    parser.add_argument(
        "--html-seconds",
        type=float,
        default=None,
        help="length of the recorded session the HTML is made of (default 60, quick 15)",
    )


class _Session:
    """A daemon on a structure, and a bridge following it."""

    def __init__(self, molecule: Path, record: Path | None = None, seconds: float | None = None):
        self.dir = Path(tempfile.mkdtemp(prefix="spw"))
        self.pub, self.ctl = f"ipc://{self.dir}/pub", f"ipc://{self.dir}/ctl"
        args = ["--device", "sim:scan", "--molecule", str(molecule), "--pub", self.pub]
        args += ["--ctl", self.ctl]
        if record is not None:
            args += ["--record", str(record), "--seconds", f"{seconds:g}"]
        self.daemon = DaemonChild(args, self.dir / "daemon.log")
        self.bridge = None
        try:
            self.daemon.wait_ready(READY_S)
            if record is None:
                self.bridge = WebBridge("--connect", self.pub, "--control", self.ctl)
        except BaseException:
            self.stop()
            raise

    def stop(self) -> None:
        if self.bridge is not None:
            self.bridge.stop()
        self.daemon.stop(30.0)
        shutil.rmtree(self.dir, ignore_errors=True)


def _drawing(page: Browser, frames: int = 10) -> dict:
    return page.wait(
        lambda p: (s := p.state()) and s["frames"] >= frames and s, READY_S, "the page draws"
    )


def _frames_over(page: Browser, seconds: float) -> tuple[float, dict]:
    """Frames a second the page draws over the window, and its state at the end."""
    start, t0 = page.state(), time.monotonic()
    time.sleep(seconds)
    end, t1 = page.state(), time.monotonic()
    return (end["frames"] - start["frames"]) / (t1 - t0), end


def _floor_ms(size: tuple[int, int]) -> float:
    """A finished frame of one full-screen pass of one colour at this picture size (ms)."""
    with Browser(size=size) as page:
        page.open("about:blank")
        width, height, ms = page.run(_FLOOR_JS, FLOOR_FRAMES)
    if (width, height) != tuple(size):
        raise UserError(f"the floor's canvas is {width}x{height}, not {size[0]}x{size[1]}")
    return ms


def _sessions(ctx: BenchContext, structures, sizes, seconds: float) -> list[dict]:
    rows = []
    floors = {size: _floor_ms(size) for size in sizes}
    runs = [(e, size) for e in structures for size in sizes]
    session = current = None
    try:
        for entry, size in progress(runs, desc="bench web: pages", total=len(runs)):
            if current is not entry:
                if session is not None:
                    session.stop()
                session, current = _Session(entry.path), entry
            with Browser(size=size) as page:
                page.open(session.bridge.url)
                _drawing(page)
                page.run("window.sasprobe.timeDraws()")
                time.sleep(0.5 if ctx.smoke else 2.0)  # the cube's atoms are in, the JIT warm
                fps, state = _frames_over(page, seconds)
            latency = state.get("latency_ms") or [None, None]
            draw = state.get("draw_ms") or [None, None]
            rows.append(
                {
                    "structure": entry.id,
                    "atoms": state["atoms"],
                    "size": list(size),
                    "fps": fps,
                    "draw_p50_ms": draw[0],
                    "draw_p95_ms": draw[1],
                    "draw_fps": 1000.0 / draw[0] if draw[0] else None,
                    "floor_ms": floors[size],
                    "latency_p50_ms": latency[0],
                    "latency_p95_ms": latency[1],
                    "cube_atoms": state["cube_atoms"],
                    "drawn_atoms": state["drawn_atoms"],
                    "load_average_1min": os.getloadavg()[0],
                }
            )
    finally:
        if session is not None:
            session.stop()
    return rows


class _Gaps:
    """The longest gap between the publish times of consecutive poses, from a subscriber:
    poses the scene's `pose_every` ticks apart (the daemon publishes every Nth above 2 kHz)."""

    def __init__(self, pub: str) -> None:
        import zmq

        self.worst_ns = 0
        self.poses = 0
        self._stop = threading.Event()
        self._sock = zmq.Context.instance().socket(zmq.SUB)
        self._sock.rcvhwm = 1_000_000
        self._sock.setsockopt(zmq.SUBSCRIBE, b"pose")
        self._sock.setsockopt(zmq.SUBSCRIBE, b"scene")
        self._sock.connect(pub)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from sasprobe.protocol.pose import POSE_TOPIC, decode_pose
        from sasprobe.protocol.scene import decode_scene

        last, stride = None, None
        while not self._stop.is_set():
            if not self._sock.poll(50):
                continue
            topic, payload = self._sock.recv_multipart()
            if topic != POSE_TOPIC:
                stride = decode_scene(payload).get("pose_every", 1)
                continue
            pose = decode_pose(payload)
            if last is not None and pose.seq == last[0] + (stride or 1):
                self.worst_ns = max(self.worst_ns, pose.publish_t_ns - last[1])
            last = (pose.seq, pose.publish_t_ns)
            self.poses += 1

    def window(self, seconds: float) -> dict:
        self.worst_ns, self.poses = 0, 0
        time.sleep(seconds)
        return {"worst_gap_ms": self.worst_ns / 1e6, "poses": self.poses}

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._sock.close(linger=0)


# The page's script never returns, from a moment after the driver's call has.
STALL = "setTimeout(() => { for (;;) {} }, 300)"


def _pages(molecule: Path, counts: list[int], total: int, seconds: float) -> tuple[list, dict]:
    """The bridge's CPU with each count of pages, then the daemon's worst pose gap idle and
    with `total` pages of which one is stalled (one daemon and bridge throughout)."""
    session = _Session(molecule)
    gaps = _Gaps(session.pub)
    pages: list[Browser] = []

    def grow(n: int) -> None:
        while len(pages) < n:
            page = Browser(size=SMALL)
            pages.append(page)
            page.open(session.bridge.url)
            _drawing(page, 3)

    try:
        idle = gaps.window(seconds)
        rows = []
        for n in progress(counts, desc="bench web: pages", total=len(counts)):
            grow(n)
            time.sleep(1.0)
            c0, t0 = session.bridge.cpu_s(), time.monotonic()
            f0 = sum(p.state()["frames"] for p in pages)
            time.sleep(seconds)
            c1, t1 = session.bridge.cpu_s(), time.monotonic()
            f1 = sum(p.state()["frames"] for p in pages)
            cpu = 100 * (c1 - c0) / (t1 - t0)
            rows.append({"pages": n, "cpu_percent": cpu, "poses_sent_per_s": (f1 - f0) / (t1 - t0)})
        for r in rows:
            extra = r["cpu_percent"] - rows[0]["cpu_percent"]
            r["cpu_percent_per_page"] = extra / r["pages"] if r["pages"] else None
        grow(total)
        pages[0].run(STALL)
        time.sleep(2.0)
        f0 = [p.state()["frames"] for p in pages[1:]]
        loaded = gaps.window(seconds)
        f1 = [p.state()["frames"] for p in pages[1:]]
        return rows, {
            "pages": total,
            "stalled": 1,
            "idle": idle,
            "with_pages": loaded,
            "gap_increase_ms": loaded["worst_gap_ms"] - idle["worst_gap_ms"],
            "others_fps_median": statistics.median((b - a) / seconds for a, b in zip(f0, f1)),
        }
    finally:
        for page in pages:
            with contextlib.suppress(Exception):  # the stalled page may not answer: it goes
                page.close()
        gaps.close()
        session.stop()


def _html(molecule: Path, entry_id: str, seconds: float) -> dict:
    folder = Path(tempfile.mkdtemp(prefix="spwh"))
    try:
        recording, html = folder / "session.mcap", folder / "session.html"
        session = _Session(molecule, record=recording, seconds=seconds)
        session.daemon.finish(seconds + READY_S)
        session.stop()
        t0 = time.perf_counter()
        r = subprocess.run(
            [sys.executable, "-m", "sasprobe", "replay", str(recording), "--html", str(html)],
            capture_output=True,
            text=True,
            timeout=600 + 10 * seconds,
        )
        build_s = time.perf_counter() - t0
        if r.returncode != 0:
            raise RuntimeError(f"replay --html failed: {r.stderr.strip()[-300:]}")
        size = html.stat().st_size
        with Browser(size=SMALL) as page:
            t0 = time.perf_counter()
            page.open(html.as_uri())
            page.wait(
                lambda p: (s := p.state()) and s.get("loaded") and s["frames"] > 0,
                READY_S,
                "the HTML opens",
            )
            load_s = time.perf_counter() - t0
            duration = page.state()["duration_s"]
        minutes = max(duration, 1e-9) / 60
        return {
            "structure": entry_id,
            "session_s": duration,
            "bytes": size,
            "mb_per_minute": size / 1e6 / minutes,
            "build_s": build_s,
            "load_s": load_s,
            "load_s_per_minute": load_s / minutes,
        }
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def run(ctx: BenchContext, args=None) -> BenchResult:
    find_browser()  # UserError: skipped, saying what is missing
    by_id = {e.id: e for e in reference_structures()}
    if "1crn" not in by_id:
        raise UserError("no reference structures (tests/data/pdb)")
    seconds = getattr(args, "seconds", None) or (1.0 if ctx.smoke else 4.0 if ctx.quick else 10.0)
    html_s = getattr(args, "html_seconds", None) or (3.0 if ctx.smoke else 15 if ctx.quick else 60)
    wanted = ["1crn"] if ctx.smoke else ["1crn", "1aon"] if ctx.quick else ["1crn", "1aon", "6zu5"]
    structures = [by_id[i] for i in wanted if i in by_id]
    big = by_id["1crn" if ctx.smoke else "1aon" if "1aon" in by_id else "1crn"]
    sizes = [(320, 180)] if ctx.smoke else [(1280, 720), (960, 540)]
    counts = [0, 1] if ctx.smoke else [0, 1, 2, 4]
    cpu, gaps = _pages(big.path, counts, 2 if ctx.smoke else 4 if ctx.quick else 10, seconds)
    data = {
        "targets": TARGETS,
        "sessions": _sessions(ctx, structures, sizes, seconds),
        "bridge_cpu": cpu,
        "pose_gaps": gaps | {"structure": big.id},
        "html": _html(big.path, big.id, html_s),
        "bridge_cpu_structure": big.id,
    }
    return BenchResult("web", data, _markdown(data), _charts(ctx, data))


def _f(v, digits=0) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def _ratio(a, b) -> str:
    return "-" if a is None or not b else f"{a / b:.1f}"


def _markdown(d: dict) -> str:
    lines = [
        "Each page follows a daemon (simulated arm, scan) through `sasprobe web` in headless "
        "Chromium (SwiftShader), at the browser's own pacing. Draw time: a frame drawn and "
        "finished (a pixel read back after it; SwiftShader draws only what is read), last 200 "
        "frames; frames/s shown: frames the page drew over the window; latency: from the "
        "daemon publishing a pose to the bridge hearing the page drew it; floor: a finished "
        "frame of one full-screen pass writing one colour on a blank page at that size, the "
        "least any page that writes every pixel once costs here.",
        "",
        f"Targets: {d['targets']}.",
        "",
        "| structure | atoms | picture | draw p50 / p95 (ms) | frames/s drawable (1 / p50) "
        "| floor (ms) | draw p50 / floor | frames/s shown | latency p50 / p95 (ms) "
        "| cube atoms (drawn) | load avg |",
        "|---|---:|---|---|---:|---:|---:|---:|---|---|---:|",
    ]
    for r in d["sessions"]:
        lines.append(
            f"| {r['structure'].upper()} | {r['atoms']} | {r['size'][0]}x{r['size'][1]} "
            f"| {_f(r['draw_p50_ms'], 1)} / {_f(r['draw_p95_ms'], 1)} | {_f(r['draw_fps'], 1)} "
            f"| {_f(r['floor_ms'], 1)} | {_ratio(r['draw_p50_ms'], r['floor_ms'])} "
            f"| {_f(r['fps'], 1)} | {_f(r['latency_p50_ms'], 1)} / {_f(r['latency_p95_ms'], 1)} "
            f"| {r['cube_atoms']} ({r['drawn_atoms']}) | {r['load_average_1min']:.1f} |"
        )
    lines += [
        "",
        f"Bridge CPU ({d['bridge_cpu_structure'].upper()}, pages at {SMALL[0]}x{SMALL[1]} with "
        "the browser's own pacing):",
        "",
        "| pages | bridge CPU | poses sent / s | CPU per page |",
        "|---:|---:|---:|---:|",
    ]
    for r in d["bridge_cpu"]:
        per = "-" if r["cpu_percent_per_page"] is None else f"{r['cpu_percent_per_page']:.2f} %"
        lines.append(
            f"| {r['pages']} | {r['cpu_percent']:.2f} % | {r['poses_sent_per_s']:.0f} | {per} |"
        )
    g, h = d["pose_gaps"], d["html"]
    lines += [
        "",
        f"The daemon's worst pose gap ({g['structure'].upper()}): idle "
        f"{g['idle']['worst_gap_ms']:.3f} ms, with {g['pages']} pages of which one is stalled "
        f"{g['with_pages']['worst_gap_ms']:.3f} ms ({g['gap_increase_ms']:+.3f} ms); the other "
        f"pages drew {g['others_fps_median']:.1f} frames/s (median).",
        "",
        f"HTML of a {h['session_s']:.0f} s {h['structure'].upper()} session: "
        f"{h['bytes'] / 1e6:.2f} MB ({h['mb_per_minute']:.2f} MB a minute), written in "
        f"{h['build_s']:.1f} s, opened and drawn in {h['load_s']:.2f} s "
        f"({h['load_s_per_minute']:.2f} s a minute).",
    ]
    return "\n".join(lines)


def _charts(ctx: BenchContext, d: dict) -> list[Path]:
    charts = []
    path = ctx.chart_path("web_fps.png")
    if path is not None:
        fig, ax = figure()
        sizes = sorted({tuple(r["size"]) for r in d["sessions"]}, reverse=True)
        names = list(dict.fromkeys(r["structure"] for r in d["sessions"]))
        width = 0.8 / max(len(sizes), 1)
        for k, size in enumerate(sizes):
            xs, ys = [], []
            for i, name in enumerate(names):
                row = next(
                    (
                        r
                        for r in d["sessions"]
                        if r["structure"] == name and tuple(r["size"]) == size
                    ),
                    None,
                )
                if row is not None:
                    xs.append(i + k * width)
                    ys.append(row["draw_fps"] or 0.0)
            bars = ax.bar(xs, ys, width, label=f"{size[0]}x{size[1]}")
            floor = next(r["floor_ms"] for r in d["sessions"] if tuple(r["size"]) == size)
            if floor:  # the most frames/s a full-screen pass allows at this size
                ax.axhline(1000.0 / floor, color=bars.patches[0].get_facecolor(), ls="--", lw=1)
        ax.axhline(60, color="k", ls=":", lw=1)
        ax.set_xticks([i + width * (len(sizes) - 1) / 2 for i in range(len(names))])
        ax.set_xticklabels([n.upper() for n in names])
        ax.set_ylabel("frames / s (1 / draw time p50)")
        ax.set_title(
            "Session page in headless Chromium (SwiftShader)\n"
            "dotted: 60; dashed: one full-screen pass of one colour"
        )
        ax.legend(fontsize=8)
        charts.append(save(fig, path))
    path = ctx.chart_path("web_bridge_cpu.png")
    if path is not None:
        fig, ax = figure()
        rows = d["bridge_cpu"]
        ax.plot([r["pages"] for r in rows], [r["cpu_percent"] for r in rows], "o-")
        ax.set_xlabel("pages")
        ax.set_ylabel("bridge CPU (% of one core)")
        ax.set_title(f"sasprobe web following {d['bridge_cpu_structure'].upper()}")
        charts.append(save(fig, path))
    return charts
