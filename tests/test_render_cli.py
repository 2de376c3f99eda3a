"""`sasprobe render` through the real CLI: headless images, videos, the G-buffer file
format, every reference structure, and one clear line for every bad input."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest
from sasprobe.molecule import load_structure

from tests.conftest import run_cli

SMALL = "160x120"


@pytest.fixture(scope="module", autouse=True)
def needs_gl(gl):
    """The CLI renders in its own process; this skips the module where no EGL context can be
    made."""


def render(*args, timeout=180, **kwargs):
    return run_cli("render", "--headless", *args, timeout=timeout, **kwargs)


def one_line_error(result, *words):
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("sasprobe"), lines[0]
    for w in words:
        assert w in lines[0], lines[0]


def test_png_and_gbuffer_file_format(tmp_path):
    png, npz = tmp_path / "x.png", tmp_path / "g.npz"
    r = render(
        "--size",
        "200x150",
        "--out",
        str(png),
        "--gbuffer",
        str(npz),
        "--probe",
        "8,12,6",
        "--nav-cube",
        "9,11,7,6",
        "--clip",
        "0,0,1,-3",
        "--probe-plane",
    )
    assert r.returncode == 0, r.stderr
    image = iio.imread(png)
    assert image.shape[:2] == (150, 200)
    g = np.load(npz)
    expected = {
        "atom_id": (np.int32, (150, 200)),
        "kind": (np.uint8, (150, 200)),
        "position": (np.float32, (150, 200, 3)),
        "normal": (np.float32, (150, 200, 3)),
        "view": (np.float64, (4, 4)),
        "proj": (np.float64, (4, 4)),
        "viewport": (np.int32, (2,)),
        "nav_cube": (np.float64, (4,)),
        "nav_cube_axes": (np.float64, (3, 3)),
        "probe": (np.float64, (4,)),
        "clip_planes": (np.float64, (2, 4)),
    }
    lighting = {
        "shadow_dir",
        "shadow_probe",
        "ao",
        "light_direction",
        "probe_light",
    }  # tests/test_render_lighting_render.py
    assert set(expected) <= set(g.files) and set(g.files) - set(expected) <= lighting
    for key, (dtype, shape) in expected.items():
        assert g[key].dtype == dtype and g[key].shape == shape, key
    assert tuple(g["viewport"]) == (200, 150)
    np.testing.assert_allclose(g["nav_cube"], [9, 11, 7, 6])
    np.testing.assert_array_equal(
        g["nav_cube_axes"], np.eye(3)
    )  # standalone: the cube is not turned
    np.testing.assert_allclose(g["probe"], [8, 12, 6, 1.4])
    np.testing.assert_allclose(
        g["clip_planes"][0], [0, 0, 1, -3]
    )  # the user's, then the probe plane
    probe_plane = g["clip_planes"][1]  # at most a probe radius behind the probe centre
    assert -1.4 - 1e-9 <= probe_plane[:3] @ [8, 12, 6] + probe_plane[3] <= 1e-9
    assert (g["atom_id"] == -1).sum() > 0 and (g["atom_id"] >= 0).sum() > 0
    assert np.all((g["atom_id"] == -1) == (g["kind"] == 0))
    # Conventions: each ray-cast pixel's world position, projected with proj @ view
    # (column vectors), lands on that pixel's centre, row 0 at the top. (Backbone pixels
    # hold the trace's centre line, a few pixels off across the line's width.)
    assert {1, 2, 3, 4} <= set(np.unique(g["kind"]).tolist())
    rows, cols = np.nonzero((g["kind"] > 0) & (g["kind"] != 3))
    p = np.concatenate(
        [g["position"][rows, cols].astype(np.float64), np.ones((rows.size, 1))], axis=1
    )
    clip = p @ (g["proj"] @ g["view"]).T
    ndc = clip[:, :3] / clip[:, 3:]
    x = (ndc[:, 0] + 1) / 2 * 200
    y = (1 - ndc[:, 1]) / 2 * 150
    assert np.abs(x - (cols + 0.5)).max() < 0.6 and np.abs(y - (rows + 0.5)).max() < 0.6
    # Unit normals wherever something is drawn.
    np.testing.assert_allclose(np.linalg.norm(g["normal"][rows, cols], axis=1), 1.0, atol=1e-4)


def test_camera_spec_is_used_verbatim(tmp_path):
    npz = tmp_path / "g.npz"
    r = render(
        "--size",
        SMALL,
        "--camera",
        "eye=40,30,60 target=10,12,8 up=0,0,1 fov=30",
        "--gbuffer",
        str(npz),
    )
    assert r.returncode == 0, r.stderr
    g = np.load(npz)
    view = g["view"]
    eye = np.linalg.inv(view)[:3, 3]
    np.testing.assert_allclose(eye, [40, 30, 60], atol=1e-9)
    forward = -view[2, :3]
    np.testing.assert_allclose(
        forward,
        (np.array([10, 12, 8]) - eye) / np.linalg.norm(np.array([10, 12, 8]) - eye),
        atol=1e-9,
    )
    assert view[1, 2] > 0.5  # up = +z appears upward
    np.testing.assert_allclose(g["proj"][1, 1], 1 / np.tan(np.radians(15)), rtol=1e-12)


def test_every_reference_structure_renders(tmp_path, reference_entries):
    for entry in reference_entries:
        png, npz = tmp_path / f"{entry.id}.png", tmp_path / f"{entry.id}.npz"
        r = run_cli(
            "render",
            "--headless",
            "--molecule",
            str(entry.path),
            "--size",
            SMALL,
            "--out",
            str(png),
            "--gbuffer",
            str(npz),
            timeout=300,
        )
        assert r.returncode == 0, f"{entry.id}: {r.stderr}"
        g = np.load(npz)
        n_atoms = load_structure(entry.path).n_atoms
        ids = g["atom_id"][g["atom_id"] >= 0]
        assert ids.size > 0.1 * g["atom_id"].size and ids.max() < n_atoms, entry.id
        assert iio.imread(png).shape[:2] == (120, 160)


def test_video_and_numbered_frames(tmp_path):
    mp4 = tmp_path / "orbit.mp4"
    r = render("--size", SMALL, "--frames", "4", "--orbit", "20", "--out", str(mp4))
    assert r.returncode == 0, r.stderr
    import imageio.v2 as imageio  # the ffmpeg reader of imageio-ffmpeg

    with imageio.get_reader(mp4, format="FFMPEG") as reader:
        frames = np.stack([frame for frame in reader])
    assert frames.shape[0] == 4 and frames.shape[1:3] == (120, 160)
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 2, (
        "the orbit should change the picture"
    )
    png = tmp_path / "f.png"
    r = render("--size", SMALL, "--frames", "3", "--out", str(png))
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in tmp_path.glob("f_*.png")) == [
        "f_0000.png",
        "f_0001.png",
        "f_0002.png",
    ]


def test_a_render_says_where_its_picture_went(tmp_path):
    """Without a display and without --out, the picture goes to a default file in the
    working folder, and one line says so (before, it was drawn and dropped, in silence)."""
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = run_cli("render", "--size", SMALL, env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout == "wrote sasprobe-render.png (no display: drawn headless)\n"
    assert iio.imread(tmp_path / "sasprobe-render.png").shape[:2] == (120, 160)
    r = render("--size", SMALL, "--frames", "2", env=env, cwd=tmp_path)  # asked to be headless
    assert r.returncode == 0 and r.stdout == "wrote sasprobe-render.mp4\n", r.stderr
    out = tmp_path / "asked.png"
    r = render("--size", SMALL, "--out", str(out), "--snapshot", str(tmp_path / "s.png"))
    assert r.stdout == f"wrote {out}\nwrote {tmp_path / 's.png'}\n", r.stderr


@pytest.mark.parametrize(
    "args,words",
    [
        (["--size", "100"], ["--size", "WIDTHxHEIGHT"]),
        (["--size", "10x10"], ["--size", "16.."]),
        (["--camera", "eye=1,2"], ["--camera", "3 finite"]),
        (["--camera", "pos=1,2,3"], ["--camera", "pos=1,2,3"]),
        (["--camera", "eye=1,2,3 target=1,2,3"], ["same point"]),
        (["--camera", "fov=200"], ["fov"]),
        (["--clip", "0,0,0,1"], ["normal"]),
        (["--nav-cube", "1,2,3,-4"], ["half edge"]),
        (["--out", "x.jpg"], [".png"]),
        (["--frames", "2", "--seconds", "1"], ["--frames or --seconds"]),
        (["--gbuffer", "g.txt"], [".npz"]),
        (["--molecule", "no/such/file.pdb"], ["no such file"]),
        (["--touched", "99999"], ["--touched"]),
    ],
)
def test_bad_input_is_one_line(args, words):
    one_line_error(render(*args), *words)


def test_no_egl_is_one_line(monkeypatch):
    # glvnd finds no EGL vendor library: no EGL device at all.
    monkeypatch.setenv("__EGL_VENDOR_LIBRARY_FILENAMES", "/nonexistent/egl_vendor.json")
    one_line_error(render("--size", SMALL), "EGL")


def test_too_old_opengl_is_one_line(monkeypatch):
    # Mesa then reports an OpenGL 3.3 context.
    monkeypatch.setenv("MESA_GL_VERSION_OVERRIDE", "3.3")
    one_line_error(render("--size", SMALL), "OpenGL 4.1", "3.3")


@pytest.mark.parametrize(
    "args, samples",
    [
        (["--preset", "soft"], 64),  # a still waits for the ray-traced AO to converge
        (["--connect", "--preset", "soft"], 64),  # one frame of the daemon's session too
        (["--connect", "--preset", "soft", "--seconds", "3", "--out", "s.mp4"], 0),
        (["--connect", "--ao", "reference", "--frames", "30", "--out", "s.mp4"], 0),
        (["--connect", "--preset", "soft", "--seconds", "3", "--samples", "8"], 8),
    ],
)
def test_a_live_video_does_not_wait_for_convergence(args, samples):
    """A video following a daemon films the session as it goes: with the soft preset, 90
    frames of 3 s were 2 pictures, each frame waiting for 64 AO samples per pixel."""
    from sasprobe.cli.lighting_args import lighting_from_args
    from sasprobe.cli.main import build_parser

    parsed = build_parser({"render"}).parse_args(["render", "--headless", *args])
    assert lighting_from_args(parsed, headless=True)[0].samples == samples
