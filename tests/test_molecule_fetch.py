"""Structures by PDB id against a real HTTP server on loopback (started here) serving the
reference data's gzipped mmCIF: a miss downloads into the cache (with a progress bar for a
large file), a hit works with the server gone, the embedded entry's id needs no server, and
being offline without a cache, an unknown id, a server error or a page that is not mmCIF
each end in one line."""

from __future__ import annotations

import gzip
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import gemmi
import pytest
from sasprobe.molecule import load_structure_or_default
from sasprobe.molecule.fetch import FetchError, FetchSettings, fetch_entry, pdb_id

from tests.conftest import run_cli


class Archive(BaseHTTPRequestHandler):
    """GET /{ID}.cif.gz -> the entry; /broken/... -> HTTP 500; /html/... -> a web page."""

    entries: dict[str, bytes] = {}
    requests: list[str] = []

    def do_GET(self):  # noqa: N802 (http.server's name)
        self.requests.append(self.path)
        name = self.path.rsplit("/", 1)[-1]
        if self.path.startswith("/broken/"):
            self.send_error(500, "Internal Server Error")
            return
        body = (
            b"<html>maintenance</html>"
            if self.path.startswith("/html/")
            else self.entries.get(name)
        )
        if body is None:
            self.send_error(404, "Not Found")
            return
        self.send_response(200)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):  # keep the test output clean
        pass


@pytest.fixture(scope="module")
def archive(reference_by_id):
    oky = gemmi.read_structure(str(reference_by_id["1oky"].path))
    oky.setup_entities()
    Archive.entries = {
        "6ZU5.cif.gz": reference_by_id["6zu5"].path.read_bytes(),
        "1OKY.cif.gz": gzip.compress(oky.make_mmcif_document().as_string().encode()),
    }
    server = ThreadingHTTPServer(("127.0.0.1", 0), Archive)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


def dead_port() -> str:
    import socket

    with socket.socket() as s:  # a port nothing listens on once closed
        s.bind(("127.0.0.1", 0))
        return f"http://127.0.0.1:{s.getsockname()[1]}"


def test_ids_and_files():
    assert pdb_id("pdb:4HHB") == "4hhb" and pdb_id("1crn") == "1crn"
    assert pdb_id("structure.pdb") is None and pdb_id("12345") is None
    with pytest.raises(FetchError, match="not a PDB id"):
        pdb_id("pdb:hhb")


def test_miss_then_hit_offline(archive, tmp_path):
    """The CLI fetches 6ZU5 (3.8 MB: a progress bar), then reads it from the cache with the
    mirror unreachable."""
    cache = tmp_path / "cache"
    before = len(Archive.requests)
    r = run_cli("info", "6zu5", "--pdb-mirror", archive + "/{ID}.cif.gz", "--pdb-cache", str(cache))
    assert r.returncode == 0, r.stderr
    assert "165175" in r.stdout and "fetch 6zu5" in r.stderr
    assert (cache / "6zu5.cif.gz").read_bytes() == Archive.entries["6ZU5.cif.gz"]
    assert Archive.requests[before:] == ["/6ZU5.cif.gz"]
    settings = FetchSettings(mirror=dead_port() + "/{ID}.cif.gz", cache=cache)
    assert fetch_entry("6zu5", settings) == cache / "6zu5.cif.gz"  # no request: the cache answers
    assert len(Archive.requests) == before + 1


def test_the_embedded_entry_needs_no_server(tmp_path, crambin):
    """`1crn` and `pdb:1crn` name the shipped copy: no request, nothing cached, offline."""
    settings = FetchSettings(mirror=dead_port() + "/{ID}.cif.gz", cache=tmp_path / "cache")
    for text in ("1crn", "pdb:1CRN"):
        s = load_structure_or_default(text, fetch=settings)
        assert s.sha256 == crambin.sha256 and s.n_atoms == 327
    assert not (tmp_path / "cache").exists()
    r = run_cli(
        "sas", "1crn", "--pdb-mirror", dead_port() + "/{id}.cif", "--pdb-cache", str(tmp_path)
    )
    assert r.returncode == 0 and r.stdout.startswith("1crn: SAS"), r.stderr


def test_mirror_from_the_environment_and_the_config_file(archive, tmp_path, reference_by_id):
    atoms = load_structure_or_default(str(reference_by_id["1oky"].path)).n_atoms  # the PDB file
    cache = tmp_path / "cache"
    s = load_structure_or_default(
        "pdb:1oky", fetch=FetchSettings(mirror=archive + "/{ID}.cif.gz", cache=cache)
    )
    assert s.n_atoms == atoms and s.source == str(cache / "1oky.cif.gz")
    env_cache, toml_cache = tmp_path / "env", tmp_path / "toml"
    import os

    env = dict(
        os.environ, SASPROBE_PDB_MIRROR=archive + "/{ID}.cif.gz", SASPROBE_PDB_CACHE=str(env_cache)
    )
    r = run_cli("sas", "1oky", env=env)
    assert (
        r.returncode == 0 and "1oky: SAS" in r.stdout and (env_cache / "1oky.cif.gz").is_file()
    ), r.stderr
    config = tmp_path / "sasprobe.toml"
    config.write_text(
        f'[info]\npdb-mirror = "{archive}/{{ID}}.cif.gz"\npdb-cache = "{toml_cache}"\n'
    )
    r = run_cli("--config", str(config), "info", "pdb:1oky")
    assert (
        r.returncode == 0 and str(atoms) in r.stdout and (toml_cache / "1oky.cif.gz").is_file()
    ), r.stderr


@pytest.mark.parametrize(
    "mirror, ident, message",
    [
        ("{dead}/{{ID}}.cif.gz", "1abc", "cannot reach 127.0.0.1"),
        ("{server}/{{ID}}.cif.gz", "9zzz", "no such entry at 127.0.0.1"),
        ("{server}/broken/{{ID}}.cif.gz", "1crn", "answered HTTP 500"),
        ("{server}/html/{{ID}}.cif.gz", "1crn", "did not send an mmCIF file"),
    ],
)
def test_failures_are_one_line(archive, tmp_path, mirror, ident, message):
    mirror = mirror.format(dead=dead_port(), server=archive)
    with pytest.raises(FetchError, match=message):
        fetch_entry(ident, FetchSettings(mirror=mirror, cache=tmp_path))
    assert not list(tmp_path.iterdir()), "nothing is cached from a failed fetch"


def test_offline_without_cache_through_the_cli(tmp_path):
    r = run_cli(
        "info", "pdb:1abc", "--pdb-mirror", dead_port() + "/{id}.cif", "--pdb-cache", str(tmp_path)
    )
    assert r.returncode == 2 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert (
        len(lines) == 1 and "pdb:1abc: cannot reach" in lines[0] and "no copy is cached" in lines[0]
    ), r.stderr
    r = run_cli("info", "1abc", "--pdb-mirror", "nowhere", "--pdb-cache", str(tmp_path))
    assert (
        r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "neither rcsb" in r.stderr
    )
