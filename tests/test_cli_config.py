"""One TOML file for everything the flags set: sections are commands, keys long options."""

from __future__ import annotations

import json
import os

from tests.conftest import run_cli


def _info_probe_radius(*args, env=None) -> tuple[int, float | None, str]:
    out = run_cli(*args, "info", "--json", env=env) if env else run_cli(*args, "info", "--json")
    value = json.loads(out.stdout)["probe_radius"] if out.returncode == 0 else None
    return out.returncode, value, out.stderr


def test_file_sets_defaults_and_flags_win(tmp_path):
    cfg = tmp_path / "lab.toml"
    cfg.write_text("[info]\nprobe-radius = 1.1\n[sas]\npoints = 64\n")
    assert _info_probe_radius("--config", str(cfg))[1] == 1.1
    out = run_cli("--config", str(cfg), "info", "--json", "--probe-radius", "1.3")
    assert json.loads(out.stdout)["probe_radius"] == 1.3
    sas = run_cli("--config", str(cfg), "sas", "--json")
    assert json.loads(sas.stdout)["points"] == 64


def test_environment_and_default_location(tmp_path):
    cfg = tmp_path / "env.toml"
    cfg.write_text("[info]\nprobe_radius = 0.9\n")  # underscores accepted too
    env = dict(os.environ, SASPROBE_CONFIG=str(cfg))
    assert _info_probe_radius(env=env)[1] == 0.9
    home = tmp_path / "xdg"
    (home / "sasprobe").mkdir(parents=True)
    (home / "sasprobe" / "config.toml").write_text("[info]\nprobe-radius = 1.25\n")
    env = {k: v for k, v in os.environ.items() if k != "SASPROBE_CONFIG"}
    env["XDG_CONFIG_HOME"] = str(home)
    assert _info_probe_radius(env=env)[1] == 1.25


def test_bad_config_gives_one_line(tmp_path):
    cases = {
        "[info]\nprobe-radius = -2\n": "probe-radius",
        "[info]\nnonsense = 1\n": "no option 'nonsense'",
        "[warp]\n": "unknown section [warp]",
        "[info]\njson = 3\n": "true or false",
        "info = 3\n": "must be a [section]",
        "[info\n": "not valid TOML",
    }
    for i, (text, needle) in enumerate(cases.items()):
        cfg = tmp_path / f"bad{i}.toml"
        cfg.write_text(text)
        code, _, stderr = _info_probe_radius("--config", str(cfg))
        lines = stderr.strip().splitlines()
        assert code == 2 and len(lines) == 1 and needle in lines[0] and str(cfg) in lines[0], (
            text,
            stderr,
        )
    code, _, stderr = _info_probe_radius("--config", str(tmp_path / "missing.toml"))
    assert code == 2 and "not found" in stderr


def test_template_lists_every_command_and_round_trips(tmp_path):
    out = run_cli("config", "--template")
    assert out.returncode == 0
    for section in ("[info]", "[sas]", "[bench]"):
        assert section in out.stdout
    # uncommenting every option that has a concrete default gives a valid, accepted file
    body = []
    for raw in out.stdout.splitlines():
        if raw.startswith("["):
            body.append(raw)
        elif raw.startswith("# ") and " = " in raw and "<value>" not in raw:
            body.append(raw[2:].split("    #")[0])
    cfg = tmp_path / "all.toml"
    cfg.write_text("\n".join(body) + "\n")
    assert run_cli("--config", str(cfg), "info").returncode == 0
