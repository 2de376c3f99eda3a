"""Run the pages' command lines as a user would on a fresh clone, offline.

Each page runs in a folder of its own (with `tests/data` reachable as in a checkout) as a
new user: empty configuration, cache and key folders, no display. A PDB id is fetched from
a mirror on loopback (`Mirror`) that serves tests/data/pdb/ as mmCIF. Each command runs in
a process forked from a server that has already imported sasprobe and its libraries
(`multiprocessing`'s forkserver), so a short command costs a fork rather than a Python
start-up; it runs `sasprobe.cli.main.main` as the `sasprobe` script does, with its own
working folder, environment, stdout and stderr. A command that hangs past its limit
prints every thread's stack and ends.

What changes from the page's text is said in `adapted()`: a daemon and its clients meet on
free loopback ports rather than the default ones (a daemon someone runs on this machine is
never met), durations are short, pictures small, and a mirror or host named on a line is
the loopback one.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads in the fork server

import gzip  # noqa: E402
import json  # noqa: E402
import multiprocessing  # noqa: E402
import re  # noqa: E402
import signal  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer  # noqa: E402
from pathlib import Path  # noqa: E402
from urllib.parse import urlsplit  # noqa: E402
from urllib.request import urlopen  # noqa: E402

import gemmi  # noqa: E402, F401  (loaded once, in the fork server)
import numpy  # noqa: E402, F401
import zmq  # noqa: E402, F401

import sasprobe.cli.main  # noqa: E402
from tests.conftest import REPO_ROOT  # noqa: E402
from tests.support.daemon_process import free_port  # noqa: E402
from tests.support.pages import Line  # noqa: E402

sasprobe.cli.main.build_parser()  # every command's module and what it imports to register

FORK = multiprocessing.get_context("forkserver")
FORK.set_forkserver_preload([__name__])
COMMAND_LIMIT_S = 300.0  # a command still running then prints its stacks and ends
READY_LIMIT_S = 120.0  # a daemon's start-up on a loaded machine (imports, structure, grid)
STOP_LIMIT_S = 30.0

# Shorter runs than the pages' (their outputs are checked, not their length).
DEMO_SECONDS = 2.0
DAEMON_SECONDS = 8.0
MAX_FRAMES = 8
MAX_SAMPLES = 8
MAX_WIDTH = 480
REPLAY_FPS = 5
DEVICES_SIMULATED = ("sim", "replay")
# What a daemon, a demo or a renderer is run on instead of a complex of 60,000 atoms or
# more: the same commands, at a cost the suite can pay on a software rasteriser.
SMALLER = {
    "tests/data/pdb/1aon.pdb.gz": "tests/data/pdb/1oky.pdb.gz",
    "tests/data/pdb/6zu5.cif.gz": "tests/data/pdb/1oky.pdb.gz",
    "6zu5": "1oky",
}


def _child(argv: list[str], cwd: str, env: dict, out: str, err: str, limit_s: float) -> None:
    """In the forked process: become `sasprobe ARGV` run in `cwd` with `env`."""
    import faulthandler
    import sys

    os.chdir(cwd)
    os.environ.clear()
    os.environ.update(env)
    for fd, path, flags in (
        (0, os.devnull, os.O_RDONLY),
        (1, out, os.O_WRONLY | os.O_CREAT | os.O_TRUNC),
        (2, err, os.O_WRONLY | os.O_CREAT | os.O_TRUNC),
    ):
        opened = os.open(path, flags, 0o644)
        os.dup2(opened, fd)
        os.close(opened)
    sys.stdout.reconfigure(line_buffering=True)  # events reach the file as they happen
    faulthandler.enable()
    faulthandler.dump_traceback_later(limit_s, exit=True)
    raise SystemExit(sasprobe.cli.main.main(list(argv)))


class Command:
    """One `sasprobe` process: started at once; `wait()` for its end, `stop()` to signal it."""

    count = 0
    _lock = threading.Lock()

    def __init__(self, argv: list[str], cwd: Path, env: dict, logs: Path, limit_s: float) -> None:
        with Command._lock:
            Command.count += 1
            n = Command.count
        self.argv = argv
        self.cwd = cwd
        self.out_path = logs / f"{n:03d}.out"
        self.err_path = logs / f"{n:03d}.err"
        self.started = time.monotonic()
        self.seconds: float | None = None
        self.process = FORK.Process(
            target=_child,
            args=(argv, str(cwd), env, str(self.out_path), str(self.err_path), limit_s),
        )
        self.process.start()

    @property
    def stdout(self) -> str:
        return self.out_path.read_text(errors="replace") if self.out_path.exists() else ""

    @property
    def stderr(self) -> str:
        return self.err_path.read_text(errors="replace") if self.err_path.exists() else ""

    def events(self) -> dict[str, dict]:
        """The JSON events on its stdout (a daemon's ready and stopped), by name."""
        found = {}
        for line in self.stdout.splitlines():
            try:
                event = json.loads(line)
            except ValueError:
                continue
            if isinstance(event, dict) and "event" in event:
                found[event["event"]] = event
        return found

    def alive(self) -> bool:
        return self.process.is_alive()

    def wait(self, timeout_s: float = COMMAND_LIMIT_S + 30.0) -> int:
        self.process.join(timeout_s)
        if self.process.is_alive():  # past its own limit too: no stacks came
            self.process.kill()
            self.process.join(10.0)
        if self.seconds is None:
            self.seconds = time.monotonic() - self.started
        return self.process.exitcode

    def stop(self, sig: int = signal.SIGTERM) -> int:
        if self.alive():
            os.kill(self.process.pid, sig)
        return self.wait(STOP_LIMIT_S)

    def wait_ready(self) -> bool:
        """A daemon: True once it is ready, False when it ended first or is still not ready
        after READY_LIMIT_S (then it is made to print its stacks and end)."""
        deadline = time.monotonic() + READY_LIMIT_S
        while time.monotonic() < deadline:
            if "ready" in self.events():
                return True
            if not self.alive():
                return "ready" in self.events()
            time.sleep(0.05)
        self.stop(signal.SIGABRT)  # faulthandler prints every thread's stack on SIGABRT
        return False


@dataclass
class Ran:
    """What one line did: the command as run, its exit status and output, its folder."""

    line: Line
    argv: list[str]
    returncode: int | None
    stdout: str
    stderr: str
    folder: Path
    seconds: float
    events: dict = field(default_factory=dict)
    skipped: str | None = None  # why it did not run here
    daemon: dict | None = None  # the pub and ctl endpoints the line talked to
    status: dict | None = None  # a daemon line: its status once it was ready

    def __str__(self) -> str:
        return (
            f"{self.line}\n  ran: sasprobe {' '.join(self.argv)} (in {self.folder}, "
            f"{self.seconds:.1f} s)\n  exit status {self.returncode}\n  stdout: "
            f"{self.stdout[-1500:]}\n  stderr: {self.stderr[-1500:]}"
        )


class Mirror:
    """A PDB mirror on loopback: GET .../{id}.cif.gz is tests/data/pdb/'s entry as mmCIF."""

    def __init__(self) -> None:
        entries: dict[str, bytes] = {}
        self.requests: list[str] = []
        requests = self.requests

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self):  # noqa: N802 (http.server's name)
                requests.append(self.path)
                ident = self.path.rsplit("/", 1)[-1].split(".")[0].lower()
                body = entries.get(ident) or _entry(ident)
                if body is None:
                    self.send_error(404, "Not Found")
                    return
                entries[ident] = body
                self.send_response(200)
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args):
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.template = f"http://127.0.0.1:{self.server.server_address[1]}/{{mid}}/{{id}}.cif.gz"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def _entry(ident: str) -> bytes | None:
    data = REPO_ROOT / "tests" / "data" / "pdb"
    if (data / f"{ident}.cif.gz").is_file():
        return (data / f"{ident}.cif.gz").read_bytes()
    if not (data / f"{ident}.pdb.gz").is_file():
        return None
    st = gemmi.read_structure(str(data / f"{ident}.pdb.gz"))
    st.setup_entities()
    return gzip.compress(st.make_mmcif_document().as_string().encode())


def fresh_environment(root: Path, mirror: Mirror) -> dict:
    """A new user's environment: nothing configured, cached or keyed yet; no display."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith("SASPROBE_") and k not in ("DISPLAY", "WAYLAND_DISPLAY")
    }
    home = root / "home"
    for folder in (home / ".config", home / ".cache", home / "run"):
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    # Mesa's compiled shaders are the machine's, not the user's: the one cache the suite fills
    cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    env.setdefault("MESA_SHADER_CACHE_DIR", str(Path(cache) / "mesa_shader_cache"))
    env.update(
        HOME=str(home),
        XDG_CONFIG_HOME=str(home / ".config"),
        XDG_CACHE_HOME=str(home / ".cache"),
        XDG_RUNTIME_DIR=str(home / "run"),
        SASPROBE_PDB_MIRROR=mirror.template,
        PYTHONUNBUFFERED="1",
    )
    return env


def page_folder(root: Path, name: str) -> Path:
    """An empty working folder where `tests/data/...` resolves as in a checkout."""
    folder = root / "pages" / name
    (folder / "tests").mkdir(parents=True)
    (folder / "tests" / "data").symlink_to(REPO_ROOT / "tests" / "data")
    return folder


def _option(argv: list[str], name: str) -> str | None:
    if name in argv and argv.index(name) + 1 < len(argv):
        return argv[argv.index(name) + 1]
    return None


def _set_option(argv: list[str], name: str, value: str) -> list[str]:
    if name in argv:
        argv = list(argv)
        argv[argv.index(name) + 1] = value
        return argv
    return [*argv, name, value]


def _without(argv: list[str], *names: str) -> list[str]:
    """`argv` less the options `names` and their values."""
    out, skip = [], False
    for word in argv:
        if skip:
            skip = False
        elif word in names:
            skip = True
        else:
            out.append(word)
    return out


def _smaller_size(text: str) -> str:
    width, height = (int(v) for v in text.split("x"))
    while width > MAX_WIDTH:
        width, height = width // 2, height // 2
    return f"{width - width % 2}x{height - height % 2}"


def adapted(argv: list[str], folder: Path, mirror: Mirror) -> list[str]:
    """The page's command as the test runs it: shorter, smaller, on the loopback mirror."""
    command = argv[0] if argv else ""
    if command in ("daemon", "demo", "render"):
        argv = [SMALLER.get(word, word) for word in argv]
    if command == "demo":
        seconds = _option(argv, "--seconds")
        if seconds is None or float(seconds) > DEMO_SECONDS:
            argv = _set_option(argv, "--seconds", f"{DEMO_SECONDS:g}")
    if command == "daemon":
        seconds = _option(argv, "--seconds")
        if seconds is not None and float(seconds) > DAEMON_SECONDS:
            argv = _set_option(argv, "--seconds", f"{DAEMON_SECONDS:g}")
    if command == "replay" and "--video" in argv:
        argv = _set_option(argv, "--fps", f"{REPLAY_FPS:g}")
        argv = _set_option(argv, "--size", _option(argv, "--size") or "1280x720")
    if command in ("render", "replay", "demo"):
        for name, limit in (("--frames", MAX_FRAMES), ("--samples", MAX_SAMPLES)):
            value = _option(argv, name)
            if value is not None and int(value) > limit:
                argv = _set_option(argv, name, str(limit))
    if command == "render" and "--samples" not in argv and "--help" not in argv:
        argv = _set_option(argv, "--samples", str(MAX_SAMPLES))  # a still's progressive effects
        size = _option(argv, "--size") or ("1280x720" if command == "render" else None)
        if size is not None and "--help" not in argv:  # a render's default size, too
            argv = _set_option(argv, "--size", _smaller_size(size))
    if "--pdb-mirror" in argv:
        argv = _set_option(argv, "--pdb-mirror", mirror.template)
    return argv


def needs_daemon(argv: list[str]) -> bool:
    return bool(argv) and (
        argv[0] in ("status", "set", "mark", "findings")
        or (argv[0] in ("render", "web") and "--help" not in argv and connects(argv))
    )


def connects(argv: list[str]) -> bool:
    """A render that follows the daemon (`--connect`); the web page always does."""
    return argv[0] == "web" or "--connect" in argv


def simulated(argv: list[str]) -> bool:
    device = _option(argv, "--device") or "sim"
    return device.split(":")[0] in DEVICES_SIMULATED


def daemon_endpoints(argv: list[str], folder: Path) -> tuple[list[str], dict]:
    """A daemon line on free loopback ports (or its ipc:// paths moved into the page's
    folder); the endpoints its clients are given."""
    endpoints = {}
    for name in ("--pub", "--ctl"):
        given = _option(argv, name)
        if given is not None and given.startswith("ipc://"):
            value = f"ipc://{folder / Path(given[len('ipc://') :]).name}"
        else:
            value = f"tcp://127.0.0.1:{free_port()}"
        argv = _set_option(argv, name, value)
        endpoints[name] = value
    return argv, {"pub": endpoints["--pub"], "ctl": endpoints["--ctl"]}


def client_endpoints(argv: list[str], daemon: dict) -> list[str]:
    """A client line pointed at the running daemon (the page's default or its host)."""
    if argv[0] == "web":
        return _set_option(
            _set_option(argv, "--connect", daemon["pub"]), "--control", daemon["ctl"]
        )
    if argv[0] == "render":
        argv = list(argv)
        at = argv.index("--connect")
        if at + 1 < len(argv) and not argv[at + 1].startswith("-"):
            argv[at + 1] = daemon["pub"]
        else:
            argv.insert(at + 1, daemon["pub"])
        return _set_option(argv, "--control", daemon["ctl"])
    return _set_option(argv, "--ctl", daemon["ctl"])


def scheduled_ticks(argv: list[str]) -> int:
    """The last tick of a daemon line's injected faults and button presses (0: none)."""
    last = 0
    for k, word in enumerate(argv[:-1]):
        if word in ("--inject-fault", "--inject-button"):
            numbers = [int(n) for n in re.findall(r"\d+", argv[k + 1].split("@", 1)[1])]
            last = max(last, sum(numbers))
    return last


def reads_file(argv: list[str]) -> str | None:
    """The recording a line reads (`replay FILE`, `daemon --device replay:FILE`), or None."""
    if argv and argv[0] == "replay" and len(argv) > 1:
        return argv[1]
    device = _option(argv, "--device") or ""
    return device.split(":", 1)[1] if device.startswith("replay:") else None


class PageSession:
    """A page's lines run in order in one folder: a daemon line keeps running (as in a
    second terminal) for the lines after it in its block, which talk to it; a line that
    talks to a daemon where none runs gets a simulated one; a daemon line whose arm is
    missing ends in its error, and a simulated daemon with its other options takes its
    place for the rest of the block."""

    def __init__(
        self, name: str, root: Path, env: dict, mirror: Mirror, files: dict | None = None
    ) -> None:
        self.folder = page_folder(root, name)
        for file, text in (files or {}).items():  # what the page shows a user writing
            (self.folder / file).write_text(text)
        self.logs = root / "logs" / name
        self.logs.mkdir(parents=True)
        self.env = env
        self.mirror = mirror
        self.results: list[Ran] = []
        self.daemon: Command | None = None
        self.daemon_line: Line | None = None
        self.daemon_status: dict | None = None  # its status once it was ready
        self.endpoints: dict | None = None

    def run(self, lines: list[Line], skip, setup: dict | None = None) -> list[Ran]:
        """Run `lines` in order; `skip(line)` says why a line is not run here (or None);
        `setup[line.text]`: commands that make what that line reads, run before it."""
        block = object()
        for line in lines:
            if line.block != block:
                self.end_daemon()
                block = line.block
            for argv in (setup or {}).get(line.text, []):
                if argv[0] == "daemon":
                    argv, _ = daemon_endpoints(argv, self.folder)
                made = self.command(argv)
                if made.wait() != 0:
                    raise AssertionError(f"setup of {line}: sasprobe {argv}: {made.stderr}")
            why = skip(line)
            if why is not None:
                self.results.append(
                    Ran(line, line.args, None, "", "", self.folder, 0.0, skipped=why)
                )
                continue
            self.run_line(line)
        self.end_daemon()
        return self.results

    def command(self, argv: list[str], limit_s: float = COMMAND_LIMIT_S) -> Command:
        return Command(argv, self.folder, self.env, self.logs, limit_s)

    def run_line(self, line: Line) -> None:
        argv = adapted(line.args, self.folder, self.mirror)
        if argv[0] == "daemon" and "--help" not in argv:
            self.start_daemon(line, argv)
            return
        read = reads_file(argv)
        if self.daemon is not None and read is not None and read == self.daemon_records():
            self.end_daemon()  # its recording is read once it is finished
        endpoints = None
        if needs_daemon(argv):
            if self.daemon is None:  # a session of the page's own kind: recorded
                self.start_daemon(None, ["daemon", "--record", f"session-{Command.count}.mcap"])
            endpoints = self.endpoints
            argv = client_endpoints(argv, endpoints)
        cmd = self.command(argv)
        rc = self.serve_once(cmd) if argv[0] == "web" and "--help" not in argv else cmd.wait()
        out = cmd.stdout
        if line.stdout_to is not None:  # the shell's `> FILE`
            (self.folder / line.stdout_to).write_text(out)
        self.results.append(
            Ran(line, argv, rc, out, cmd.stderr, self.folder, cmd.seconds, daemon=endpoints)
        )

    def serve_once(self, cmd: Command) -> int:
        """A server (`sasprobe web`) runs until it prints its page's URL; the page is asked
        for once as a browser would (its status line goes to the end of the output, after
        `fetched: `), then the server ends as Ctrl+C ends it."""
        deadline = time.monotonic() + READY_LIMIT_S
        while time.monotonic() < deadline and cmd.alive() and "\n" not in cmd.stdout:
            time.sleep(0.05)
        url = cmd.stdout.split("\n", 1)[0].strip()
        if cmd.alive() and url.startswith("http://"):
            parts = urlsplit(url)
            try:  # the printed host may be this machine's name: its loopback serves it too
                with urlopen(f"http://127.0.0.1:{parts.port}{parts.path}", timeout=60) as reply:
                    fetched = f"{reply.status} {reply.headers.get_content_type()}"
            except OSError as exc:
                fetched = f"failed: {exc}"
            cmd.stop(signal.SIGINT)
            with open(cmd.out_path, "a") as out:
                out.write(f"fetched: {fetched}\n")
        return cmd.wait()

    def daemon_records(self) -> str | None:
        return _option(self.daemon.argv, "--record") if self.daemon is not None else None

    def start_daemon(self, line: Line | None, argv: list[str]) -> None:
        self.end_daemon()
        argv, endpoints = daemon_endpoints(argv, self.folder)
        cmd = self.command(argv)
        if not cmd.wait_ready():
            rc = cmd.wait()
            if line is not None:
                self.results.append(
                    Ran(line, argv, rc, cmd.stdout, cmd.stderr, self.folder, cmd.seconds)
                )
            if simulated(argv):
                return
            # no arm here: the simulated arm takes its place for the lines that follow (its
            # session is not the page's: it records nothing)
            self.start_daemon(None, _without(argv, "--device", "--pub", "--ctl", "--record"))
            return
        self.daemon, self.daemon_line, self.endpoints = cmd, line, endpoints
        self.daemon_status = self.status() if reads_file(argv) is None else None
        ticks = scheduled_ticks(argv)
        if ticks:
            self.wait_for_tick(ticks + 200)

    def status(self) -> dict | None:
        """The running daemon's status, asked as a user would (None: no answer)."""
        status = self.command(["status", "--json", "--ctl", self.endpoints["ctl"]])
        status.wait()
        try:
            return json.loads(status.stdout)
        except ValueError:
            return None

    def wait_for_tick(self, tick: int) -> None:
        """Until the daemon's loop has passed `tick`."""
        deadline = time.monotonic() + READY_LIMIT_S
        while time.monotonic() < deadline and self.daemon.alive():
            status = self.status()
            if status is not None and status["loop"]["total"]["ticks"] >= tick:
                return
            time.sleep(0.2)
        raise AssertionError(f"the daemon did not reach tick {tick}: {self.daemon.stderr}")

    def end_daemon(self) -> None:
        """The block's daemon ends: by its own --seconds if it has them, else as Ctrl+C ends it."""
        cmd, line = self.daemon, self.daemon_line
        if cmd is None:
            return
        self.daemon = self.daemon_line = None
        seconds = _option(cmd.argv, "--seconds")
        if seconds is not None or reads_file(cmd.argv) is not None:  # it ends by itself
            cmd.wait(float(seconds or 0) + COMMAND_LIMIT_S)
        elif cmd.alive():
            time.sleep(max(0.0, 0.5 - (time.monotonic() - cmd.started)))
            cmd.stop(signal.SIGINT)
        rc = cmd.wait()
        if line is not None:
            self.results.append(
                Ran(
                    line,
                    cmd.argv,
                    rc,
                    cmd.stdout,
                    cmd.stderr,
                    self.folder,
                    cmd.seconds,
                    events=cmd.events(),
                    daemon=self.endpoints,
                    status=self.daemon_status,
                )
            )
