"""`sasprobe demo`: the daemon with the simulated arm and a renderer following it.

Two processes, started the way a user would start them (`sasprobe daemon ...` and
`sasprobe render --connect ...`) on ipc:// sockets in a private temporary folder, so
two demos never collide. This process watches the daemon over the public protocol (a
pose subscriber for the force and contact figures, the control channel for the loop's
rate and jitter), shows progress, stops both children (the daemon first: it writes zero
force before it exits) and writes summary.json.

On a shared, small machine the software rasteriser would take every core from the
1 kHz loop, so the daemon asks for SCHED_FIFO (its default), which no ordinary process
can preempt. Where that is refused (no root or CAP_SYS_NICE) the renderer runs at a
lower priority and, headless, with one llvmpipe thread.
"""

from __future__ import annotations

import json
import shlex
import shutil
import signal
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from sasprobe.cli.bench.machine import cpu_steal_ticks
from sasprobe.cli.children import Child, DaemonChild, child_env
from sasprobe.cli.demo_report import ForceMonitor, demo_summary, print_summary
from sasprobe.common.errors import UserError

DEFAULT_SECONDS = 10.0  # headless
HEADLESS_SIZE = (640, 360)
WINDOW_SIZE = (1280, 720)
RENDERER_NICE = 10  # the haptic loop comes first
DAEMON_READY_S = 90.0  # start-up on a loaded machine: imports, structure, grid
OVERVIEW_FIRST_S = 1.0  # the headless video opens on the whole molecule, the cube on it
RENDER_START_GRACE_S = 90.0  # renderer start-up (imports, GL context, structure) beyond --seconds
DAEMON_STOP_S = 10.0
RENDER_STOP_S = 20.0  # it finishes the video first
POLL_S = 0.1
STATUS_EVERY_S = 1.0

# Options the demo sets itself; passing them through --render-args/--daemon-args would break it.
RESERVED_RENDER = (
    "--connect",
    "--control",
    "--molecule",
    "--headless",
    "--out",
    "--snapshot",
    "--report",
    "--seconds",
    "--frames",
    "--size",
    "--fps",
    "--keys",
    "--overview-first",
)
RESERVED_DAEMON = (
    "--device",
    "--molecule",
    "--pub",
    "--ctl",
    "--record",
    "--report",
    "--seconds",
    "--no-realtime",
    "--keep-water",
    "--keys",
)


@dataclass
class DemoOptions:
    molecule: str | None = None
    device: str = "sim:scan"
    headless: bool = False
    # None: DEFAULT_SECONDS headless, until the window closes otherwise
    seconds: float | None = None
    out: Path = Path("sasprobe-demo")
    size: tuple[int, int] | None = None
    fps: float = 10.0
    record: Path | None = None
    realtime: bool = True
    keep_water: bool = False
    keys: Path | None = None  # CURVE keys for both children (and the demo's own clients)
    render_args: list[str] = field(default_factory=list)
    daemon_args: list[str] = field(default_factory=list)


def split_extra_args(text: str | None, reserved: tuple[str, ...], flag: str) -> list[str]:
    """Extra options passed through to a child, refusing the ones the demo sets itself."""
    if not text:
        return []
    try:
        args = shlex.split(text)
    except ValueError as exc:
        raise UserError(f"{flag}: {exc}") from None
    for arg in args:
        name = arg.split("=", 1)[0]
        if name in reserved:
            raise UserError(f"{flag}: {name} is set by the demo itself (see sasprobe demo --help)")
    return args


class DemoSession:
    def __init__(self, opts: DemoOptions) -> None:
        self.opts = opts
        # short: ipc paths hold ~100 bytes
        self.sockets = Path(tempfile.mkdtemp(prefix="sasprobe-demo-"))
        self.pub = f"ipc://{self.sockets}/pub"
        self.ctl = f"ipc://{self.sockets}/ctl"
        self.out = opts.out
        self.video = self.out / "demo.mp4"
        self.snapshot = self.out / "snapshot.png"
        self.render_report = self.sockets / "render.json"
        self.children: list[Child] = []  # every child started, in order (the daemon first)
        self.daemon: Child | None = None
        self.renderer: Child | None = None
        self.monitor: ForceMonitor | None = None
        self.control = None
        self.ready: dict = {}
        self.status_end: dict | None = None
        self.steal_from = self.steal_to = None  # the machine's CPU times over the measured window
        self.last_status: dict | None = None  # the newest answer, should the daemon end by itself
        self.exit_report: dict | None = None
        self.renderer_rc: int | None = None
        self.daemon_rc: int | None = None
        self.notes: list[str] = []
        self.hurry = threading.Event()

    # ------------------------------------------------------------ start
    def start_daemon(self) -> None:
        from sasprobe.protocol.client import ControlClient

        o = self.opts
        argv = ["--device", o.device, "--pub", self.pub, "--ctl", self.ctl]
        if o.molecule:
            argv += ["--molecule", str(Path(o.molecule).resolve())]
        if o.keep_water:
            argv.append("--keep-water")
        if not o.realtime:
            argv.append("--no-realtime")
        if o.keys:
            argv += ["--keys", str(Path(o.keys).resolve())]
        if o.record:
            argv += ["--record", str(Path(o.record).resolve())]
        self.daemon = DaemonChild(
            argv + o.daemon_args, self.sockets / "daemon.log", registry=self.children
        )
        ready = self.ready = self.daemon.wait_ready(DAEMON_READY_S)
        if o.realtime and not ready.get("realtime"):
            self.notes.append(
                "real-time scheduling was refused (needs root or CAP_SYS_NICE): the haptic rate "
                "may drop while the renderer runs"
            )
        keys = None
        if o.keys:
            from sasprobe.protocol.security import load_client_keys

            keys = load_client_keys(Path(o.keys))
        self.control = ControlClient(self.ctl, keys=keys, timeout_s=3.0)
        device = self.control.status()["device"]  # the ratings the forces are measured against
        self.monitor = ForceMonitor(
            self.pub,
            device["limits"]["continuous_force_n"],
            device["limits"]["nominal_rate_hz"],
            keys,
        )

    def _render_argv(self, headless: bool, seconds: float | None) -> list[str]:
        o = self.opts
        size = o.size or (HEADLESS_SIZE if headless else WINDOW_SIZE)
        argv = [
            sys.executable,
            "-m",
            "sasprobe",
            "render",
            "--connect",
            self.pub,
            "--control",
            self.ctl,
            "--size",
            f"{size[0]}x{size[1]}",
            "--report",
            str(self.render_report),
        ]
        if o.keep_water:
            argv.append("--keep-water")
        if o.keys:
            argv += ["--keys", str(Path(o.keys).resolve())]
        if headless:
            argv += [
                "--headless",
                "--seconds",
                f"{seconds:g}",
                "--fps",
                f"{o.fps:g}",
                "--out",
                str(self.video),
                "--snapshot",
                str(self.snapshot),
                "--overview-first",
                f"{OVERVIEW_FIRST_S:g}",
            ]
        elif seconds is not None:
            argv += ["--seconds", f"{seconds:g}"]
        return argv + o.render_args

    def start_renderer(self, headless: bool, seconds: float | None) -> None:
        env = child_env()
        # no ordinary process can preempt a SCHED_FIFO loop
        protected = bool(self.ready.get("realtime"))
        if not protected and headless:
            env.setdefault("LP_NUM_THREADS", "1")  # Mesa llvmpipe: leave the loop a core of its own
        self.renderer = Child(
            "render",
            self._render_argv(headless, seconds),
            self.sockets / "render.log",
            env=env,
            nice=0 if protected else RENDERER_NICE,
            registry=self.children,
        )

    def begin_window(self) -> None:
        """The measured window, the demo proper, begins: the renderer draws the session."""
        self._status(reset=True)
        self.steal_from = cpu_steal_ticks()

    def end_window(self) -> None:
        """The measured window ends: the daemon's last status, and the machine's CPU times."""
        self.status_end, self.steal_to = self._status(), cpu_steal_ticks()

    def _status(self, reset: bool = False) -> dict | None:
        if self.control is None or self.daemon is None or not self.daemon.alive():
            return None
        try:
            self.last_status = self.control.status(reset_stats=reset)
        except UserError:
            return None
        return self.last_status

    # ------------------------------------------------------------ run
    def watch(self, headless: bool, seconds: float | None) -> None:
        """Until the renderer ends (its --seconds, or the window closed) or the daemon stops."""
        from sasprobe.common.progress import progress_bar

        bar = progress_bar(
            seconds if headless else None,
            "demo",
            unit="s",
            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} s{postfix}"
            if headless
            else "{desc}: {n:.0f} s{postfix}",
        )
        deadline = time.monotonic() + (seconds or 0.0) + RENDER_START_GRACE_S if headless else None
        rendering_since = None
        shown = 0.0
        next_status = 0.0
        try:
            while self.renderer.alive() and self.daemon.alive():
                time.sleep(POLL_S)
                self.monitor.poll()
                now = time.monotonic()
                if rendering_since is None and (not headless or self.video.exists()):
                    rendering_since = now  # the first frame is in the video
                    self.begin_window()
                if now >= next_status:
                    next_status = now + STATUS_EVERY_S
                    bar.set_postfix_str(self._progress_text(), refresh=False)
                if rendering_since is not None:
                    elapsed = (
                        min(now - rendering_since, seconds) if headless else now - rendering_since
                    )
                    if elapsed > shown:
                        bar.update(elapsed - shown)
                        shown = elapsed
                if deadline is not None and now > deadline:
                    raise UserError(
                        f"the renderer did not finish within {seconds + RENDER_START_GRACE_S:g} s "
                        f"(see its last words: {self.renderer.error_line() or 'none'})"
                    )
        finally:
            bar.close()

    def _progress_text(self) -> str:
        status = self._status()
        parts = []
        if status is not None and status["loop"]["recent"]["rate_hz"]:
            parts.append(f"haptic {status['loop']['recent']['rate_hz']:.0f} Hz")
        force = self.monitor.last_force()
        if force is not None:
            parts.append(f"force {force:.2f} N")
        contact = self.monitor.contact_fraction()
        if contact is not None:
            parts.append(f"contact {100 * contact:.0f} %")
        return ", ".join(parts)

    # ------------------------------------------------------------ stop
    def stop(self) -> None:
        """Daemon first (zero force), then the renderer; bounded waits, SIGKILL as the last resort.
        A second Ctrl+C while stopping skips the waits."""
        previous = (
            signal.signal(signal.SIGINT, lambda *_: self.hurry.set())
            if threading.current_thread() is threading.main_thread()
            else None
        )
        try:
            if self.monitor is not None:
                self.monitor.poll()
            if self.status_end is None:
                self.end_window()
            for child in self.children:
                child.signal(signal.SIGTERM)
            for child in self.children:
                rc = child.finish(
                    DAEMON_STOP_S if child is self.daemon else RENDER_STOP_S, self.hurry
                )
                if child is self.daemon:
                    self.daemon_rc, self.exit_report = rc, child.exit_report
                elif child is self.renderer:
                    self.renderer_rc = rc
            if self.monitor is not None:
                self.monitor.poll()
        finally:
            if previous is not None:
                signal.signal(signal.SIGINT, previous)

    def keep_logs(self) -> None:
        """Copy the children's stderr into --out (before close() removes the private folder)."""
        for child in self.children:
            try:
                shutil.copyfile(child.log_path, self.out / child.log_path.name)
            except OSError:
                pass

    def close(self) -> None:
        if self.monitor is not None:
            self.monitor.close()
        if self.control is not None:
            self.control.close()
        shutil.rmtree(self.sockets, ignore_errors=True)

    # ------------------------------------------------------------ summary
    def renderer_report(self) -> dict | None:
        try:
            return json.loads(self.render_report.read_text())
        except (OSError, ValueError):
            return None


def run_demo(opts: DemoOptions) -> int:
    # Ctrl+C (SIGINT) stops the demo even when it was started with SIGINT ignored, as a
    # script's background job is: the daemon and the renderer take it the same way.
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.default_int_handler) if main else None
    try:
        return _run_demo(opts)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _run_demo(opts: DemoOptions) -> int:
    from sasprobe.render.gl.context import display_available

    window = not opts.headless and display_available()
    headless = not window
    seconds = opts.seconds if opts.seconds is not None else (DEFAULT_SECONDS if headless else None)
    try:
        opts.out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--out {opts.out}: cannot create ({exc.strerror or exc})") from None
    if opts.record is not None and Path(opts.record).exists():
        raise UserError(f"--record {opts.record}: already exists; record to a new file")
    # never mix an old run's files with this one's
    for stale in ("demo.mp4", "snapshot.png", "summary.json"):
        (opts.out / stale).unlink(missing_ok=True)
    session = DemoSession(opts)
    interrupted = False
    failed = True
    try:
        try:
            print(
                f"sasprobe demo: starting the daemon ({opts.device})", file=sys.stderr, flush=True
            )
            session.start_daemon()
            session.start_renderer(headless, seconds)
            what = (
                "window open (close it or press Ctrl+C to stop)"
                if window
                else f"rendering {seconds:g} s headless"
            )
            print(f"sasprobe demo: {what}", file=sys.stderr, flush=True)
            session.watch(headless, seconds)
            if (
                window
                and session.renderer.proc.poll() not in (None, 0)
                and session.renderer_report() is None
            ):
                # No window after all (e.g. no GL 4.1 on this display): the same demo, headless.
                session.notes.append(
                    f"no window ({session.renderer.error_line()}); ran headless instead"
                )
                print(f"sasprobe demo: {session.notes[-1]}", file=sys.stderr, flush=True)
                window, headless = False, True
                seconds = opts.seconds if opts.seconds is not None else DEFAULT_SECONDS
                session.renderer.finish(0)
                session.start_renderer(True, seconds)
                session.watch(True, seconds)
            session.end_window()
        except KeyboardInterrupt:
            interrupted = True
        finally:
            session.stop()
            summary = demo_summary(session, headless, seconds, interrupted)
            (opts.out / "summary.json").write_text(json.dumps(summary, indent=1))
        _check_children(session, summary, interrupted)
        failed = False
    finally:
        if failed:
            session.keep_logs()
        session.close()
    print_summary(summary, opts.out / "summary.json")
    if interrupted:
        raise KeyboardInterrupt
    return 0


def _check_children(session: DemoSession, summary: dict, interrupted: bool) -> None:
    """A child that failed (rather than being stopped) ends the demo with its own error line."""
    if interrupted:
        return
    exit_report = summary["daemon_exit"]
    if exit_report is None or exit_report.get("reason") not in ("SIGTERM", "end of replay"):
        why = session.daemon.error_line() or exit_report or f"exit status {session.daemon_rc}"
        raise UserError(f"the daemon stopped unexpectedly: {why} (logs in {session.out})")
    if summary["renderer"] is None:
        why = session.renderer.error_line() or f"exit status {session.renderer_rc}, no report"
        raise UserError(f"the renderer failed: {why} (logs in {session.out})")
