"""Every `sasprobe` command line of README.md and docs/*.md runs on a fresh clone, offline,
and does what its page says.

Each page's fenced lines run in order in a folder of their own, as a new user would run
them (tests/support/page_runner.py: a simulated daemon where a page's arm is missing,
loopback ports and mirror, short durations), the pages side by side; then the inline
spans that are whole command lines (a span the same as a line already run is not run
again). Each line's result is held against EXPECTED, written from what the page says of
that line: its comment, its paragraph. A line without an entry there fails, as does an
entry whose line is gone, so a page cannot change what it claims without this file.

Not run here: synopses (`sasprobe sas [FILE|ID] [--json|--csv]`), parsed by
tests/test_project_readme.py, and benchmarks (`sasprobe bench ...`), which take minutes to
hours by design: tests/test_cli_bench_report.py runs every benchmark at its smallest.
"""

from __future__ import annotations

import csv
import json
import re
import sys
from concurrent.futures import ThreadPoolExecutor
from urllib.parse import urlsplit

import imageio.v2 as imageio
import numpy as np
import pytest

from tests.conftest import REPO_ROOT
from tests.support.page_runner import Mirror, PageSession, Ran, fresh_environment, needs_daemon
from tests.support.pages import PLACEHOLDER, page_lines, split_comment

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 (tomli is a dependency there)
    import tomli as tomllib

PAGES = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md"))]


def page_files(page) -> dict[str, str]:
    """Files a page shows the user writing before its commands: configuration.md's TOML
    example is the `lab.toml` its `sasprobe --config lab.toml daemon` reads."""
    if page.name != "configuration.md":
        return {}
    toml = re.search(r"^```toml\n(.*?)^```", page.read_text(), re.M | re.S)
    return {"lab.toml": toml.group(1)}


WORKERS = 3  # pages side by side: most commands wait on a daemon, a renderer or the disk
# Every line of every page runs in the first test's fixture: on a loaded 2-core machine that
# takes several times the per-test limit; each command has its own (COMMAND_LIMIT_S).
pytestmark = pytest.mark.timeout(1800)


def placeholder(word: str) -> bool:
    """`FILE`, `OUT.mp4`, `...`, or a key given one (`color=SCHEME`, `KEY=VALUE`)."""
    return word == "..." or any(PLACEHOLDER.fullmatch(part) for part in word.split("="))


def why_not_run(line) -> str | None:
    words = split_comment(line.text)[0].split()
    if "[" in line.text or any(placeholder(word) for word in words):
        return "a synopsis (tests/test_project_readme.py parses it)"
    if line.args[:1] == ["bench"] and "--help" not in line.args:
        return "a benchmark (tests/test_cli_bench_report.py runs each at its smallest)"
    return None


# What a line reads that no line of its page makes: the README's replay block reads "a
# session recorded with --record", which its lab block's arm would have made.
SETUP = {
    "sasprobe replay session.mcap --html session.html": [
        ["daemon", "--device", "sim:scan", "--molecule", "tests/data/pdb/1oky.pdb.gz"]
        + ["--record", "session.mcap", "--seconds", "2"]
    ],
    "sasprobe replay session.mcap --verify # recompute every force: difference 0 N": [
        ["daemon", "--device", "sim:dive", "--molecule", "tests/data/pdb/1oky.pdb.gz"]
        + ["--record", "session.mcap", "--seconds", "2"]
    ],
}


def run_pages(root) -> tuple[list[Ran], Mirror]:
    mirror = Mirror()
    env = fresh_environment(root, mirror)
    lines = {page: page_lines(page) for page in PAGES}

    def fenced(page):
        name = page.relative_to(REPO_ROOT).as_posix().replace("/", "_")
        session = PageSession(name, root, env, mirror, page_files(page))
        todo = [line for line in lines[page] if line.block is not None]
        return session.run(todo, why_not_run, SETUP)

    with ThreadPoolExecutor(WORKERS) as pool:
        results = [ran for page_runs in pool.map(fenced, PAGES) for ran in page_runs]
    # The spans: each command once (the first page that names it), the same as a fenced line
    # not again; in WORKERS sessions of their own.
    done = {tuple(r.line.args): r for r in results if r.skipped is None and r.daemon is None}
    spans = [line for page in PAGES for line in lines[page] if line.block is None]
    first: dict[tuple, object] = {}
    todo = []
    for line in spans:
        key = tuple(line.args)
        if key in done or (key in first and not needs_daemon(line.args)):
            continue
        first.setdefault(key, line)
        todo.append(line)

    def run_spans(k):
        files = {name: text for page in PAGES for name, text in page_files(page).items()}
        session = PageSession(f"spans{k}", root, env, mirror, files)
        return session.run(todo[k::WORKERS], why_not_run)

    with ThreadPoolExecutor(WORKERS) as pool:
        span_runs = [ran for runs in pool.map(run_spans, range(WORKERS)) for ran in runs]
    ran_by_line = {id(r.line): r for r in span_runs}
    for line in spans:
        ran = ran_by_line.get(id(line)) or done.get(tuple(line.args))
        ran = ran or ran_by_line[id(first[tuple(line.args)])]
        results.append(ran if ran.line is line else Ran(**{**ran.__dict__, "line": line}))
    return results, mirror


@pytest.fixture(scope="module")
def runs(tmp_path_factory, gl):  # gl: where no headless OpenGL exists, skip (CI: fail)
    results, mirror = run_pages(tmp_path_factory.mktemp("pages"))
    yield results, mirror
    mirror.close()


# ---------------------------------------------------------------- what the pages say


def ran_clean(r: Ran) -> None:
    """Exit status 0, and nothing on stderr but progress and warnings."""
    assert r.returncode == 0, r
    assert "Traceback" not in r.stderr and "error:" not in r.stderr, r


def one_error_line(r: Ran, *fragments: str) -> None:
    """A user error: one line on stderr, exit status 2, nothing before it."""
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and r.stdout == "" and len(lines) == 1, r
    assert lines[0].startswith("sasprobe: error: "), r
    for fragment in fragments:
        assert fragment in lines[0], (fragment, r)


def says(r: Ran, *patterns: str) -> list[re.Match]:
    """Exit status 0 and each pattern found on stdout; the matches."""
    ran_clean(r)
    found = [re.search(p, r.stdout, re.M) for p in patterns]
    for pattern, match in zip(patterns, found):
        assert match is not None, (pattern, r)
    return found


def size_of(r: Ran) -> tuple[int, int]:
    width, height = r.argv[r.argv.index("--size") + 1].split("x")
    return int(width), int(height)


def picture(r: Ran, path: str, size: tuple[int, int]):
    """A PNG of that size that shows something (not one colour)."""
    image = imageio.imread(r.folder / path)
    assert image.shape[1::-1] == size, (image.shape, r)
    assert np.ptp(image[..., :3]) > 50, f"{path} is blank: {r}"
    return image


def video(r: Ran, path: str, frames: int | None = None, size=None) -> list:
    """An MP4 whose frames read back (that many, that size), not all alike."""
    with imageio.get_reader(r.folder / path) as reader:
        images = [frame for frame in reader]
    assert images, r
    if frames is not None:
        assert len(images) == frames, (len(images), frames, r)
    if size is not None:
        assert images[0].shape[1::-1] == size, r
    return images


def rendered(r: Ran) -> None:
    """A headless render says where its picture went, and it is there."""
    (match,) = says(r, r"^wrote (\S+)")
    out = match.group(1)
    if out.endswith(".png"):
        picture(r, out, size_of(r))
    else:
        video(r, out, size=size_of(r))


def rendered_to(path: str, frames: int | None = None):
    def check(r: Ran) -> None:
        says(r, rf"^wrote {re.escape(path)}")
        if path.endswith(".png"):
            picture(r, path, size_of(r))
        else:
            images = video(r, path, frames, size_of(r))
            assert not np.array_equal(images[0], images[-1]), f"{path} does not change: {r}"

    return check


def served(token: bool):
    """`sasprobe web`: its first line is the page's address (beyond loopback, with a token in
    it), and that page answers a browser's request; Ctrl+C ends it cleanly."""

    def check(r: Ran) -> None:
        ran_clean(r)
        lines = r.stdout.strip().splitlines()
        path = urlsplit(lines[0]).path
        assert lines[0].startswith("http://"), r
        assert re.fullmatch(r"/[\w-]{16,}/", path) if token else path == "/", r
        assert lines[-1] == "fetched: 200 text/html", r

    return check


def html_written(name: str):
    """`replay --html`: one page that holds its own scripts and the session."""

    def check(r: Ran) -> None:
        ran_clean(r)
        page = (r.folder / name).read_text()
        assert page.lstrip().lower().startswith("<!doctype html>"), page[:200]
        assert "<script" in page and "http://" not in page.split("<body", 1)[-1], r

    return check


def daemon_ran(reason: str = "SIGINT", structure: str | None = None, script: str | None = None):
    """A daemon that became ready, stopped for `reason` with the arm's last force zero."""

    def check(r: Ran) -> None:
        assert r.returncode == 0 and "Traceback" not in r.stderr, r
        assert "ready" in r.events and "stopped" in r.events, r
        stopped = r.events["stopped"]
        assert stopped["reason"] == reason and stopped["ticks"] > 0, r
        assert stopped["last_force_written_n"] == [0.0, 0.0, 0.0], r
        if structure is not None:
            assert r.status["structure"]["name"] == structure, r.status
        if script is not None:
            assert f"({script})" in r.status["device"]["model"], r.status

    return check


def replayed(r: Ran) -> None:
    """A replay daemon that ran its recording to the end: a pose for every recorded tick, or
    for every Nth above 1 kHz (docs/daemon.md: poses go out at 1 kHz or more); its loop
    counts one tick more: the one that found the end."""
    daemon_ran("end of replay")(r)
    recording = r.folder / r.argv[r.argv.index("--device") + 1].split(":", 1)[1]
    every = max(1, int(r.events["ready"]["rate_hz"] // 1000))
    published = -(-recorded_ticks(recording) // every)  # ticks 0, N, 2N, ...
    assert r.events["stopped"]["publisher"]["poses_sent"] == published, r


def recorded_ticks(path) -> int:
    """Ticks of a recording, read with the mcap library and the README's tables (not
    sasprobe's reader)."""
    from tests.support.recordings import reference_ticks

    return len(reference_ticks(path))


def demo_wrote(
    folder: str = "sasprobe-demo", structure: str = "1crn", recording: str | None = None
):
    """demo.md's outputs: the video (10 fps, 640x360, as long as the run), the snapshot (its
    last frame), summary.json (the rate, forces, renderer, last force zero)."""

    def check(r: Ran) -> None:
        says(r, rf"^sasprobe demo: {structure} \(")
        seconds = float(r.argv[r.argv.index("--seconds") + 1])
        video(r, f"{folder}/demo.mp4", frames=round(seconds * 10), size=(640, 360))
        picture(r, f"{folder}/snapshot.png", (640, 360))
        summary = json.loads((r.folder / folder / "summary.json").read_text())
        assert summary["structure"]["name"] == structure, summary
        assert summary["haptics"]["rate_hz"] > 0 and summary["forces"]["poses"] > 0, summary
        assert summary["renderer"]["frames"] > 0 and "poses_missed" in summary["renderer"]["daemon"]
        assert summary["daemon_exit"]["last_force_written_n"] == [0.0, 0.0, 0.0], summary
        if recording is not None:
            assert recorded_ticks(r.folder / recording) > 0, r

    return check


def listed_devices(r: Ran) -> None:
    """What is plugged in with its --device string, or that nothing is."""
    ran_clean(r)
    assert r.stdout.startswith("none found") or "--device" in r.stdout, r


def status_told(*fields: str):
    def check(r: Ran) -> None:
        says(r, r"^sasprobe daemon [\d.]+ \(pid \d+\)", *(rf"^  {f}\b" for f in fields))

    return check


def marked(label: str):
    return lambda r: says(r, rf"^mark \d+ '{re.escape(label)}' at \([-\d.]+, [-\d.]+, [-\d.]+\) Å")


def verified(r: Ran) -> None:
    says(r, r"every force as recorded \(max \|force difference\| 0 N on all \d+ ticks\)", r"-> OK$")


def video_of_the_session(path: str):
    def check(r: Ran) -> None:
        (match,) = says(r, rf"^  video +{re.escape(path)}: (\d+) frames")
        video(r, path, frames=int(match.group(1)), size=size_of(r))

    return check


def findings_into(folder: str, *marks: str, probe: str = "1.4"):
    """The table on the terminal (the bottleneck, or that no passage narrows the path; the
    verdict for the probe; touched residues); the files into the folder; the marks by their
    labels."""

    def check(r: Ran) -> None:
        says(
            r,
            r"^  (bottleneck [\d.]+ Å|verdict +no passage narrower)",
            rf"^  verdict +(a {probe} Å probe|no passage)",
            r"^  chain +residue",
        )
        found = json.loads((r.folder / folder / "findings.json").read_text())
        assert found["touched_residues"] and "bottleneck" in found, found
        for name in ("chart.png", "path.pdb", "touched_residues.tsv", "session.pml"):
            assert (r.folder / folder / name).stat().st_size > 0, (name, r)
        assert [m["label"] for m in found["marks"]] == list(marks), found["marks"]

    return check


def sas_per_chain(r: Ran) -> None:
    """The total, and per chain the area and accessible atoms: the chains add up to both."""
    total, accessible = says(r, r"SAS ([\d.]+) Å²", r"accessible atoms \(≥ 0.5 Å²\): (\d+) of")
    chains = re.findall(r"^  chain +\S+: +([\d.]+) Å² +\((\d+) accessible atoms\)", r.stdout, re.M)
    assert len(chains) > 1, r
    areas = sum(float(area) for area, _ in chains)
    assert areas == pytest.approx(float(total.group(1)), abs=0.05 * len(chains)), r
    assert sum(int(n) for _, n in chains) == int(accessible.group(1)), r


def csv_rows(path: str, columns: tuple[str, ...], rows: int):
    def check(r: Ran) -> None:
        ran_clean(r)
        with open(r.folder / path, newline="") as fh:
            table = list(csv.reader(fh))
        assert tuple(table[0]) == columns and len(table) - 1 == rows, (table[:2], len(table), r)

    return check


def fetched(ident: str, check=ran_clean):
    """Fetched by id through the mirror (the loopback one), then `check`."""

    def run(r: Ran) -> None:
        check(r)
        assert any(path.endswith(f"/{ident}.cif.gz") for path in MIRROR_REQUESTS), MIRROR_REQUESTS

    return run


MIRROR_REQUESTS: list[str] = []


# Each line as its page writes it (blanks collapsed, comment included) -> what it must do.
# Where a line has two commands (`sasprobe daemon & sasprobe render --connect`), one check
# per command, by its name.
EXPECTED = {
    # README.md
    "python3 -m venv .venv && .venv/bin/pip install -q -e . && .venv/bin/sasprobe demo": demo_wrote(),
    "sasprobe demo": demo_wrote(),
    "sasprobe devices # what is plugged in, with its --device string": listed_devices,
    "sasprobe devices --check falcon:novint.bin # open it, read 1 s with zero force, report": (
        lambda r: one_error_line(r, "Falcon firmware file not found: novint.bin")
    ),
    "sasprobe daemon --device falcon:novint.bin --molecule tests/data/pdb/1tii.pdb.gz --record session.mcap": (
        lambda r: one_error_line(r, "Falcon firmware file not found: novint.bin")
    ),
    "sasprobe render --connect # in a second terminal: the workspace view": rendered,
    "sasprobe daemon --device sim:dive --molecule tests/data/pdb/1oky.pdb.gz &": daemon_ran(
        structure="1oky", script="dive"
    ),
    "sasprobe render --connect --preset soft": rendered,
    "sasprobe status # rate, jitter, overruns, subscribers": status_told(
        "rate", "jitter", "overruns", "publisher"
    ),
    'sasprobe mark "pocket entrance" # a labelled mark at the probe': marked("pocket entrance"),
    "sasprobe replay session.mcap --verify # recompute every force: difference 0 N": verified,
    "sasprobe replay session.mcap --video session.mp4 # the session as the renderer drew it": (
        video_of_the_session("session.mp4")
    ),
    "sasprobe replay session.mcap --findings out/ # path, touched residues, marks, bottleneck": (
        findings_into("out")
    ),
    "sasprobe daemon --device replay:session.mcap # live again, for any number of renderers": replayed,
    "sasprobe demo --molecule tests/data/pdb/1aon.pdb.gz": demo_wrote(structure="1oky"),
    "sasprobe demo --molecule 6zu5": fetched("1oky", demo_wrote(structure="1oky")),
    "sasprobe daemon --help": lambda r: says(
        r, *(re.escape(scheme) for scheme in device_schemes())
    ),
    "sasprobe set stiffness=0.2": lambda r: says(r, r"^set at tick \d+: stiffness 0.2 N/mm"),
    "sasprobe config --template": lambda r: template_of_every_command(r),
    "sasprobe info 1tii": fetched("1tii", lambda r: says(r, r"^1tii ", r"atoms +5469 ")),
    # docs/benchmarks.md
    "sasprobe --help": lambda r: says(r, *(rf"^    {name} " for name in command_names())),
    "sasprobe info": lambda r: says(r, r"^1crn +\(embedded:1crn.pdb.gz\)", r"atoms +327 "),
    "sasprobe render --help": lambda r: says(r, r"--preset"),
    "sasprobe daemon --device sim": daemon_ran(),
    # docs/clients.md
    "sasprobe daemon --pub ipc:///tmp/sasprobe-pub --ctl ipc:///tmp/sasprobe-ctl &": daemon_ran(),
    "sasprobe daemon": daemon_ran(structure="1crn", script="scan"),
    # docs/configuration.md
    "sasprobe config # which file is in use": lambda r: says(r, r"^no settings file"),
    "sasprobe config --template # every option of every command, commented, with its default": (
        lambda r: template_of_every_command(r)
    ),
    "sasprobe info 1tii # RCSB, cached in ~/.cache/sasprobe/pdb": fetched(
        "1tii", lambda r: says(r, r"\.cache/sasprobe/pdb/1tii\.cif\.gz\)")
    ),
    "sasprobe render --molecule pdb:1oky --pdb-mirror pdbe # an entry from PDBe's archive": fetched(
        "ok/1oky", rendered
    ),
    'sasprobe sas 1oky --pdb-mirror "https://example.org/mmcif/{id}.cif.gz" --pdb-cache ./pdb': (
        lambda r: (says(r, r"^1oky: SAS"), (r.folder / "pdb" / "1oky.cif.gz").stat())
    ),
    "sasprobe --config lab.toml daemon": lambda r: one_error_line(
        r, "no such serial port: /dev/woodenhaptics"
    ),
    "sasprobe sas pdb:1oky": fetched("1oky", lambda r: says(r, r"^1oky: SAS")),
    "sasprobe devices": listed_devices,
    # docs/connect-your-arm.md
    "sasprobe devices # what is plugged in, with the string that selects each": listed_devices,
    "sasprobe devices --check woodenhaptics:/dev/ttyACM0 # open it, read 1 s with zero force, report": (
        lambda r: one_error_line(r, "no such serial port: /dev/ttyACM0")
    ),
    "sasprobe daemon --device woodenhaptics:/dev/ttyACM0 --molecule tests/data/pdb/1tii.pdb.gz": (
        lambda r: one_error_line(r, "no such serial port: /dev/ttyACM0")
    ),
    "sasprobe devices --check openhaptics": lambda r: one_error_line(
        r, "OpenHaptics is not installed"
    ),
    "sasprobe daemon --device inverse3 --rate 2000": lambda r: one_error_line(
        r, "no Inverse Service answers at ws://localhost:10001"
    ),
    "sasprobe status": status_told("rate", "jitter", "overruns", "publisher"),
    # docs/daemon.md
    "sasprobe daemon # simulated arm (scan script), embedded 1CRN": daemon_ran(
        structure="1crn", script="scan"
    ),
    "sasprobe daemon --molecule tests/data/pdb/1aon.pdb.gz --device sim:press --record session.mcap": (
        daemon_ran(structure="1oky", script="press")
    ),
    "sasprobe status # rate, period error, overruns, subscribers, recording": status_told(
        "rate", "jitter", "overruns", "publisher", "recording +session.mcap"
    ),
    "sasprobe set stiffness=0.2 probe-radius=1.2 cube-half=10 # or cube-half=fit / cube-half=default": (
        lambda r: says(r, r"stiffness 0.2 N/mm, .* probe 1.2 Å, .* cube half edge 10 Å$")
    ),
    "sasprobe set clip=0,0,1,-5 clip=1,0,0,-20 probe-light=off # clip=none removes them; light=X,Y,Z turns the key light": (
        lambda r: says(r, r", 2 clip plane\(s\), lights changed$")
    ),
    "sasprobe set color=chain # every renderer following it; color=default gives each its own": (
        lambda r: says(r, r", colour scheme chain$")
    ),
    "sasprobe keys keys/": lambda r: (
        says(r, r"^created keys/server.key$"),
        [(r.folder / "keys" / n).stat() for n in ("server.key_secret", "client.key_secret")],
    ),
    "sasprobe daemon --keys keys/ --pub tcp://0.0.0.0:5555 --ctl tcp://0.0.0.0:5556": daemon_ran(),
    "sasprobe render --connect tcp://lab-pc:5555 --control tcp://lab-pc:5556 --keys keys/ # on the viewer's machine": (
        rendered
    ),
    "sasprobe replay session.mcap # duration, ticks, channels, gaps": lambda r: says(
        r,
        r"^session.mcap: finished, format \d+, [\d.]+ s, \d+ ticks, 0 missing",
        r"^  messages .*ticks \d+",
    ),
    "sasprobe replay session.mcap --verify # recompute every force: max difference 0 N": verified,
    "sasprobe replay session.mcap --video session.mp4 --fps 30 --size 1280x720": (
        video_of_the_session("session.mp4")
    ),
    "sasprobe daemon --device replay:session.mcap --speed 2 # or --speed max; renderers see it live": (
        lambda r: (replayed(r), r.events["ready"]["rate_hz"] == 2000.0 or pytest.fail(str(r)))
    ),
    "sasprobe render --connect": rendered,
    # docs/demo.md
    "sasprobe demo # a window if there is a display, else 10 s headless into ./sasprobe-demo/": demo_wrote(),
    "sasprobe demo --headless --seconds 30 --molecule tests/data/pdb/1tii.pdb.gz --out tii/": demo_wrote(
        "tii", "1tii"
    ),
    "sasprobe demo --device sim:dive --daemon-args='--stiffness 0.2' --render-args=--no-fxaa": (
        demo_wrote()
    ),
    "sasprobe demo --headless --record session.mcap # keep the session, then": demo_wrote(
        recording="session.mcap"
    ),
    "sasprobe replay session.mcap --verify --video session.mp4 # recompute its forces (0 N difference) and render it": (
        lambda r: (verified(r), video_of_the_session("session.mp4")(r))
    ),
    # docs/findings.md
    "sasprobe demo --record s.mcap # or any daemon session with --record": demo_wrote(
        recording="s.mcap"
    ),
    "sasprobe replay s.mcap --findings out/ # the table on the terminal; files into out/": findings_into(
        "out"
    ),
    "sasprobe replay s.mcap --findings out/ --probe-radius 1.9 # would a larger probe get through?": (
        findings_into("out", probe="1.9")
    ),
    'sasprobe mark "entrance of the pocket" # during a session: a labelled mark at the probe': marked(
        "entrance of the pocket"
    ),
    "sasprobe findings live/ # during a session: the findings so far, on the daemon's host": lambda r: (
        says(r, r"^findings +[\d.]+ s so far, \d+ residues touched, 1 marks"),
        json.loads((r.folder / "live" / "findings.json").read_text()),
    ),
    "sasprobe daemon --molecule tests/data/pdb/1oky.pdb.gz --device sim:random --record pocket.mcap --seconds 20 &": (
        daemon_ran("time limit", structure="1oky", script="random")
    ),
    'sasprobe mark "first pocket" # 5 s in': marked("first pocket"),
    'sasprobe mark "under the loop" # 6 s later': marked("under the loop"),
    "sasprobe replay pocket.mcap --findings pocket/ # once the daemon has stopped": findings_into(
        "pocket", "first pocket", "under the loop"
    ),
    # docs/haptics.md
    "sasprobe daemon --cube-half fit # the whole SAS in the cube's drift-free core": daemon_ran(),
    "sasprobe daemon --cube-half 10 --button clutch=3 # a 10 Å half edge; button 3 is the clutch": (
        daemon_ran()
    ),
    "sasprobe set cube-half=default # back to the default size, while it runs": lambda r: says(
        r, r"cube half edge default$"
    ),
    "sasprobe daemon --device sim:dive --stiffness 0.2": daemon_ran(script="dive"),
    "sasprobe daemon --device sim:random --seed 3 --molecule tests/data/pdb/1oky.pdb.gz": daemon_ran(
        structure="1oky", script="random"
    ),
    "sasprobe daemon --inject-fault nan@900+5 --inject-button 0@2000+1500 # a NaN read; button 0 held": (
        lambda r: (
            daemon_ran()(r),
            "device fault: non-finite device state; force zeroed" in r.stderr
            or pytest.fail(str(r)),
        )
    ),
    "sasprobe sas": lambda r: says(r, r"^1crn: SAS [\d.]+ Å²", r"^  chain +A: "),
    # docs/structures.md
    "sasprobe info tests/data/pdb/1aon.pdb.gz # atoms, chains, residues, bounds, grid occupancy": (
        lambda r: says(
            r, r"^  atoms +58\d\d\d ", r"^  chains +21 +residues", r"^  bounds", r"^  grid"
        )
    ),
    "sasprobe info 1oky --json # fetched by id": fetched(
        "1oky",
        lambda r: (ran_clean(r), json.loads(r.stdout)["name"] == "1oky" or pytest.fail(str(r))),
    ),
    "sasprobe sas tests/data/pdb/1tii.pdb.gz # the total, and per chain: area and accessible atoms": (
        sas_per_chain
    ),
    "sasprobe sas tests/data/pdb/1tii.pdb.gz --csv > atoms.csv # per atom: area and accessible flag (or --json)": (
        csv_rows(
            "atoms.csv",
            ("chain", "number", "icode", "residue", "atom", "element", "area", "accessible"),
            5469,
        )
    ),
    "sasprobe sas 1crn --per-residue # chain, number, insertion code, name, atoms, area, accessible atoms": (
        lambda r: (
            says(r, r"^  chain +residue +name +atoms +area Å² +accessible$"),
            len(re.findall(r"^ +A +\d+ +[A-Z]{3} ", r.stdout, re.M)) == 46 or pytest.fail(str(r)),
        )
    ),
    "sasprobe sas 1crn --per-residue --csv > residues.csv # or --json": csv_rows(
        "residues.csv",
        ("chain", "number", "icode", "residue", "atoms", "area", "accessible_atoms"),
        46,
    ),
    # docs/viewing.md
    "sasprobe render --molecule tests/data/pdb/1tii.pdb.gz # window: drag, wheel, keys below": rendered,
    'sasprobe render --headless --molecule tests/data/pdb/1tii.pdb.gz --size 960x540 --probe 55.13,13.41,47.51 --touched 3041 --nav-cube 54,13,40,10 --camera "eye=75,50,110 target=50,14,36 fov=40" --out cube.png --gbuffer cube.npz # the picture above': (
        lambda r: (rendered_to("cube.png")(r), np.load(r.folder / "cube.npz"))
    ),
    "sasprobe render --headless --frames 120 --orbit 3 --out orbit.mp4 # a turning 1CRN as a video": (
        rendered_to("orbit.mp4", frames=8)
    ),
    "sasprobe daemon & sasprobe render --connect # follow the daemon's probe: the workspace view": {
        "daemon": daemon_ran(),
        "render": rendered,
    },
    "sasprobe render": rendered,
    # docs/web.md
    "sasprobe daemon --device sim:scan --molecule tests/data/pdb/1aon.pdb.gz # or a real arm": (
        daemon_ran(structure="1oky", script="scan")
    ),
    "sasprobe web # in a second terminal": served(token=False),
    "sasprobe web": served(token=False),
    "sasprobe web --bind 0.0.0.0": served(token=True),
    "sasprobe replay session.mcap --html session.html": html_written("session.html"),
}


def gallery(line: str):
    """viewing.md's gallery and lighting lines: the picture named by --out, at its size."""
    return rendered_to(re.search(r"--out (\S+)", line).group(1))


def device_schemes() -> list[str]:
    from sasprobe.devices.registry import SCHEMES

    return list(SCHEMES)


def command_names() -> list[str]:
    from sasprobe.cli.main import command_names as names

    return names()


def template_of_every_command(r: Ran) -> None:
    """A TOML file, commented out: a section for every command (but `config` itself)."""
    ran_clean(r)
    sections = re.findall(r"^\[(\w+)\]$", r.stdout, re.M)
    assert sections == [n for n in command_names() if n != "config"], sections
    tomllib.loads(r.stdout)


def expectation(ran: Ran):
    check = EXPECTED.get(ran.line.text)
    if check is None and re.search(r"--out (gallery_|lit|traced)", ran.line.text):
        check = gallery(ran.line.text)
    if isinstance(check, dict):
        check = check[ran.line.args[0]]
    return check


def test_every_line_runs_as_its_page_says(runs):
    results, mirror = runs
    MIRROR_REQUESTS[:] = mirror.requests
    failures, skipped = [], []
    for ran in results:
        if ran.skipped is not None:
            skipped.append(f"{ran.line}: {ran.skipped}")
            continue
        check = expectation(ran)
        if check is None:
            failures.append(f"{ran.line}: no entry in EXPECTED says what it must do")
            continue
        try:
            check(ran)
        except Exception as exc:  # a check that cannot read what it expects fails too
            failures.append(f"{ran}\n  -> {str(exc)[:2000]}")
    assert not failures, "\n\n".join(failures)


def test_every_expectation_has_its_line():
    texts = {line.text for page in PAGES for line in page_lines(page)}
    assert sorted(set(EXPECTED) - texts) == []
