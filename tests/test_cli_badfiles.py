"""The bad-file set, through the real CLI of every command that reads a file: each is one line
on stderr and exit status 2, never a traceback or a hang.

The set: a missing file, a folder, a FIFO (which would block a reader forever), /dev/zero
(which never ends), NaN and 1e30 coordinates, atoms 20,000 Å apart (a grid that cannot
fit), a gzip bomb; for recordings a corrupt zstd chunk and --recover into a missing
folder; --config and key folders too; and --inject-fault specs. `info` meets the whole set;
the other commands, which read through the same loader, one case each that shows they do.
All commands of a test run at once (start-up dominates).
"""

from __future__ import annotations

import gzip
import os
import struct

import pytest

from tests.conftest import run_cli
from tests.support.daemon_process import cli_many


def _atom(i: int, x: str, y: str = "1.000", z: str = "2.000") -> str:
    return f"ATOM  {i:5d}  CA  ALA A{i:4d}    {x:>8}{y:>8}{z:>8}  1.00  0.00           C\n"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("badfiles")
    (d / "nan.pdb").write_text(_atom(1, "nan") + _atom(2, "3.000") + "END\n")
    (d / "huge.pdb").write_text(_atom(1, "1e30") + "END\n")
    (d / "apart.pdb").write_text(
        _atom(1, "-9999.0", "-999.0", "-999.0") + _atom(2, "9999.0", "999.0", "999.0") + "END\n"
    )
    (d / "bomb.pdb.gz").write_bytes(gzip.compress(bytes(1 << 20), 9) * 1024)  # 1 MiB -> 1 GiB
    (d / "folder").mkdir()
    os.mkfifo(d / "fifo")
    return d


def _one_line(out, *needles: str) -> None:
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1 and "Traceback" not in out.stderr, (
        out.args,
        out.stderr,
    )
    for needle in needles:
        assert needle in lines[0], (out.args, lines[0])


def test_structure_commands(files):
    d = files
    cases = [
        (("info", str(d / "missing.pdb")), "no such file"),
        (("info", str(d / "folder")), "is a directory"),
        (("info", str(d / "fifo")), "is a FIFO"),
        (("info", "/dev/zero"), "is a character device"),
        (("info", str(d / "nan.pdb")), "non-finite coordinates"),
        (("info", str(d / "huge.pdb")), "beyond ±10000 Å"),
        (("info", str(d / "apart.pdb")), "grid cells"),
        (("info", str(d / "bomb.pdb.gz")), "inflates beyond"),
        (("sas", str(d / "fifo")), "is a FIFO"),
        (
            ("render", "--headless", "--molecule", str(d / "fifo"), "--out", str(d / "x.png")),
            "is a FIFO",
        ),
        (("daemon", "--molecule", str(d / "bomb.pdb.gz"), "--seconds", "1"), "inflates beyond"),
        (("daemon", "--molecule", str(d / "apart.pdb"), "--seconds", "1"), "grid cells"),
    ]
    for (_, needle), out in zip(cases, cli_many(*(args for args, _ in cases))):
        _one_line(out, needle)


def _corrupt_first_chunk(data: bytes) -> bytes:
    """Garble the compressed records of the first Chunk and clear its CRC (0 = not checked), so
    the zstd decoder itself meets the damage. Layout from the MCAP spec (mcap.dev/spec): magic
    (8 bytes), then records of opcode u8, length u64; a Chunk (opcode 6) holds start and end
    time u64, uncompressed size u64, uncompressed CRC u32, compression (u32 length + text),
    records (u64 length + bytes)."""
    out = bytearray(data)
    offset = 8
    while out[offset] != 0x06:
        offset += 9 + struct.unpack_from("<Q", out, offset + 1)[0]
    body = offset + 9
    struct.pack_into("<I", out, body + 24, 0)
    name_len = struct.unpack_from("<I", out, body + 28)[0]
    records = body + 32 + name_len + 8
    for i in range(records + 20, records + 60):
        out[i] ^= 0x5A
    return bytes(out)


def test_recording_commands(files, tmp_path):
    d = files
    good = tmp_path / "good.mcap"
    made = run_cli(
        "daemon",
        "--seconds",
        "0.5",
        "--record",
        str(good),
        "--pub",
        f"ipc://{tmp_path}/p",
        "--ctl",
        f"ipc://{tmp_path}/c",
        "--no-realtime",
    )
    assert made.returncode == 0, made.stderr
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(_corrupt_first_chunk(good.read_bytes()))
    cases = [
        (("replay", str(d / "fifo")), "is a FIFO"),
        (("replay", str(bad)), "damaged recording"),
        (("replay", str(bad), "--verify"), "damaged recording"),
        (("replay", str(good), "--recover", "/nonexistent/d/x.mcap"), "cannot create"),
        (("daemon", "--device", f"replay:{d / 'fifo'}", "--seconds", "1"), "is a FIFO"),
    ]
    for (_, needle), out in zip(cases, cli_many(*(args for args, _ in cases))):
        _one_line(out, needle)


def test_config_keys_options_and_home(files, tmp_path):
    d = files
    keys = tmp_path / "keys"
    keys.mkdir()
    os.mkfifo(keys / "client.key_secret")
    cases = [
        (("--config", str(d / "fifo"), "info"), "is a FIFO"),
        (("status", "--keys", str(keys)), "is a FIFO"),
        (("render", "--connect", "--keys", str(keys), "--headless"), "is a FIFO"),
        (("daemon", "--inject-fault", "raise@abc"), "KIND@TICK"),
        (("daemon", "--inject-fault", "nan@-5+2"), "KIND@TICK"),
        (("daemon", "--inject-fault", "raise@10+-5"), "KIND@TICK"),
        (("daemon", "--inject-fault", "melt@10"), "unknown fault kind"),
        (
            ("daemon", "--device", "woodenhaptics:/dev/null", "--inject-fault", "nan@5"),
            "only the simulated arm",
        ),
    ]
    for (_, needle), out in zip(cases, cli_many(*(args for args, _ in cases))):
        _one_line(out, needle)
    # An unreadable $HOME (here: a name too long to look up) is one warning, and the command works.
    out = run_cli("info", "--json", env=dict(os.environ, HOME="/" + "h" * 5000))
    lines = out.stderr.strip().splitlines()
    assert (
        out.returncode == 0
        and len(lines) == 1
        and lines[0].startswith("sasprobe: warning: cannot look for")
    ), out.stderr
