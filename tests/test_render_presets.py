"""Lighting presets change the picture measurably, the fitted camera fills the image with
the molecule, and the key light follows the camera (or stays in the molecule frame)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from sasprobe.molecule import load_structure
from sasprobe.render.app import RenderOptions, build_scene, initial_camera, make_renderer
from sasprobe.render.gl.targets import KIND_BACKGROUND
from sasprobe.render.lighting.presets import PRESET_NAMES, PRESETS
from sasprobe.render.lighting.settings import AOSettings

pytestmark = pytest.mark.needs_gl(430)
SIZE = (320, 240)
SAMPLES = (
    16  # ray-traced AO per pixel: the mean difference is the same as at 64 (measured 21.8 vs 21.9)
)


def render(gl, structure, opts: RenderOptions, camera=None):
    scene = build_scene(structure, opts)
    renderer = make_renderer(gl, scene, opts.size, opts)
    try:
        renderer.render(camera or initial_camera(scene, opts))
        return renderer.read_image().astype(float), renderer.targets.read(renderer.targets.ids)[
            ..., 1
        ]
    finally:
        renderer.release()


def preset_options(name: str, **lighting) -> RenderOptions:
    base = PRESETS[name].lighting
    return RenderOptions(
        size=SIZE, preset=name, lighting=replace(base, samples=SAMPLES, **lighting)
    )


@pytest.fixture(scope="module")
def tii(reference_by_id):
    return load_structure(reference_by_id["1tii"].path)


def test_presets_change_the_picture(gl, tii):
    images = {name: render(gl, tii, preset_options(name))[0] for name in PRESET_NAMES}
    unlit = render(gl, tii, preset_options("default", shadows="off", ao=AOSettings(mode="off")))[0]
    mad = lambda a, b: float(np.abs(images[a] - images[b]).mean())  # noqa: E731 (levels of 255)
    assert mad("soft", "flat") >= 20.0, mad("soft", "flat")
    # the default's shadows and AO against no lighting at all (2.3 levels before the presets)
    assert float(np.abs(images["default"] - unlit).mean()) >= 8.0
    for i, a in enumerate(PRESET_NAMES):
        for b in PRESET_NAMES[i + 1 :]:
            assert mad(a, b) >= 3.0, (a, b, mad(a, b))
    np.testing.assert_array_equal(
        images["illustrative"][0, 0], [255, 255, 255]
    )  # QuteMol's white background
    dark = np.round(np.array(PRESETS["soft"].background) * 255)
    np.testing.assert_allclose(images["soft"][0, 0], dark, atol=1)
    recoloured = render(gl, tii, replace(preset_options("flat"), background=(1.0, 1.0, 0.0)))[0]
    np.testing.assert_array_equal(
        recoloured[0, 0], [255, 255, 0]
    )  # --background wins over the preset


def test_fitted_camera_fills_the_shorter_side_on_every_shared_structure(gl, reference_entries):
    """16:9 like the default window; the molecule's pixels span at least 70 % of the height
    and never touch the border (the fit leaves 5 % either side)."""
    size = (320, 180)
    for entry in reference_entries:
        structure = load_structure(entry.path)
        _, kind = render(gl, structure, RenderOptions(size=size, fxaa=False))
        rows = np.flatnonzero((kind != KIND_BACKGROUND).any(axis=1))
        cols = np.flatnonzero((kind != KIND_BACKGROUND).any(axis=0))
        coverage = (rows[-1] - rows[0] + 1) / size[1]
        assert coverage >= 0.7, (entry.id, coverage)
        assert rows[0] > 0 and rows[-1] < size[1] - 1 and cols[0] > 0 and cols[-1] < size[0] - 1, (
            entry.id
        )


@pytest.mark.parametrize("frame, keeps_lit", [("camera", True), ("molecule", False)])
def test_key_light_follows_the_camera_or_stays_with_the_molecule(gl, crambin, frame, keeps_lit):
    """Orbit half way round: a light that follows the camera still lights the side in view;
    one fixed in the molecule frame now lights the far side."""
    opts = RenderOptions(size=SIZE, light_frame=frame, fxaa=False)
    scene = build_scene(crambin, opts)
    camera = initial_camera(scene, opts)
    image, kind = render(gl, crambin, opts, camera)
    camera.orbit(camera.up, np.pi)
    turned, turned_kind = render(gl, crambin, opts, camera)
    before = image[kind != KIND_BACKGROUND].mean()
    after = turned[turned_kind != KIND_BACKGROUND].mean()
    if keeps_lit:
        assert after > 0.85 * before, (before, after)
    else:
        assert after < 0.75 * before, (before, after)
