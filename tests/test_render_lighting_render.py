"""The lighting inside the renderer: terms computed on the impostor pipeline's own
G-buffer equal the CPU references on the exported arrays, the visibility buffer carries
them to the shading pass, path tracing replaces the lit image, `sasprobe render` takes the
lighting options, and the window's keys switch the effects."""

from __future__ import annotations

from dataclasses import replace

import imageio.v3 as iio
import numpy as np
import pytest
from sasprobe.render.camera import Camera
from sasprobe.render.gbuffer_export import gbuffer_arrays
from sasprobe.render.gl.context import GLUnavailable
from sasprobe.render.gl.targets import (
    ATOM_PROBE,
    KIND_BACKBONE,
    KIND_BACKGROUND,
    KIND_CAP,
    KIND_PROBE,
)
from sasprobe.render.gl.textures import read_texture, texture_2d
from sasprobe.render.lighting.ao.analytic import MAX_K, nearest_to_point
from sasprobe.render.lighting.ao.precomputed import OcclusionAtlas
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.settings import (
    AO_MODES,
    DEFAULT_PROBE_RANGE,
    HARD_SHADOW,
    AOSettings,
    DirectionalLight,
    LightingSettings,
    PointLight,
)
from sasprobe.render.passes.lighting import LightingPass
from sasprobe.render.renderer import Renderer
from sasprobe.render.scene_state import NavCube, Probe, SceneState

from tests.conftest import run_cli, run_window_check
from tests.references.lighting import (
    Occluders,
    analytic_ao,
    edge_cueing,
    light_visibility,
    probe_occlusion,
    view_depths,
)
from tests.support.lighting import away_from_boundaries, probe_on_surface

pytestmark = pytest.mark.needs_gl(430)  # compute shaders, storage buffers

SIZE = (160, 120)
SETUPS = ["none", "planes", "cube"]


def make_scene(structure, setup: str) -> SceneState:
    scene = SceneState(structure, probe=Probe(center=probe_on_surface(structure, (0.2, 0.3, 1.0))))
    centre = structure.positions.mean(axis=0)
    if setup == "planes":
        n = -np.array([1.0, 0.2, 0.5]) / np.linalg.norm([1.0, 0.2, 0.5])
        scene.clip_planes = [
            np.array([*n, -float(n @ centre) + 2.0]),
            np.array([0.0, 1.0, 0.0, -centre[1] + 9.0]),
        ]
    elif setup == "cube":
        scene.nav_cube = NavCube(center=centre + [2.0, -1.0, 0.0], half=9.0)
    scene.light_direction = -np.array([0.45, 0.8, 0.4]) / np.linalg.norm([0.45, 0.8, 0.4])
    return scene


def render_frame(ctx, scene, settings: LightingSettings, camera=None):
    """(renderer, G-buffer export arrays) of one frame with the lighting installed and
    switched on as `settings` says."""
    for name, on in settings.effects().items():
        setattr(scene.effects, name, on)
    renderer = Renderer(ctx, scene, SIZE)
    renderer.install_lighting(settings)
    if camera is None:
        center, radius = scene.bounding_sphere()
        camera = Camera.fitted(center, radius * 0.8, SIZE[0] / SIZE[1], direction=(0.2, 0.3, 1.0))
    renderer.render(camera)
    return renderer, gbuffer_arrays(renderer)


def render_lit(ctx, scene, cache: bool):
    """(renderer, frame): one frame of `scene` with hard shadows and analytic AO (k 16), the
    frame cache on or off."""
    settings = LightingSettings(shadows="hard", ao=AOSettings(mode="analytic", k=16))
    for name, on in settings.effects().items():
        setattr(scene.effects, name, on)
    renderer = Renderer(ctx, scene, SIZE, frame_cache=cache)
    renderer.install_lighting(settings)
    center, radius = scene.bounding_sphere()
    return renderer, renderer.render(
        Camera.fitted(center, radius * 0.8, SIZE[0] / SIZE[1], direction=(0.2, 0.3, 1.0))
    )


def occluders_of(g, scene) -> Occluders:
    s = scene.structure
    cube = g.get("nav_cube")
    culling = Culling(g["clip_planes"], None if cube is None else (cube[:3], cube[3]))
    probe = np.array([*scene.probe.center, scene.probe.radius])
    return Occluders(
        s.positions, s.vdw_radii, culling=culling, probe=probe, probe_reach=DEFAULT_PROBE_RANGE
    )


def shaded_ids(g) -> np.ndarray:
    """Atom ids where the lighting shades (backbone pixels count as background)."""
    return np.where(g["kind"] == KIND_BACKBONE, -1, g["atom_id"])


@pytest.fixture(scope="module", params=SETUPS)
def frame(request, gl, crambin):
    scene = make_scene(crambin, request.param)
    renderer, g = render_frame(
        gl, scene, LightingSettings(shadows="hard", ao=AOSettings(mode="analytic", k=16))
    )
    yield request.param, scene, renderer, g
    renderer.release()


def test_pipeline_shadows_equal_the_cpu_ray_tracer(frame):
    setup, scene, renderer, g = frame
    ids = shaded_ids(g)
    valid = ids != -1
    occ = occluders_of(g, scene)
    lights = {
        "shadow_dir": DirectionalLight(tuple(-g["light_direction"])),
        "shadow_probe": PointLight(tuple(g["probe_light"][:3]), float(g["probe_light"][3])),
    }
    for layer, light in lights.items():
        cpu = light_visibility(g["position"], g["normal"], ids, light, occ, HARD_SHADOW)
        gpu = g[layer]
        assert gpu.dtype == np.float32 and gpu.shape == ids.shape
        shadowed = cpu < 0.5
        assert 0.03 < shadowed[valid].mean() < 0.97, (setup, layer)
        compared = away_from_boundaries(shadowed, valid)
        assert ((gpu < 0.5) == shadowed)[compared].mean() >= 0.995, (setup, layer)
        assert np.all(gpu[~valid] == 1.0)


def test_pipeline_analytic_ao_equals_the_cpu_formula(frame):
    setup, scene, renderer, g = frame
    ids = shaded_ids(g)
    neighbours, _ = scene.grid.nearest_neighbors(MAX_K)
    probe_list = nearest_to_point(scene.structure.positions, scene.probe.center)
    cpu = analytic_ao(
        g["position"], g["normal"], ids, occluders_of(g, scene), neighbours, 16, probe_list
    )
    assert np.abs(g["ao"] - cpu).max() <= 1e-4, setup
    assert cpu[ids != -1].min() < 0.6


def test_the_depth_test_picks_exactly_the_background(frame):
    """The drawn passes (render/gl/depth_picked.py: shading, the traced shadows, the layered
    compose) tell the background from the surfaces by the G-buffer's depth alone: it must be
    1 exactly where the ids say background, caps, backbone trace and probe included."""
    setup, scene, renderer, g = frame
    t = renderer.targets
    depth = np.frombuffer(t.depth.read(), dtype=np.float32).reshape(SIZE[1], SIZE[0])[::-1]
    kinds = g["kind"]
    assert np.array_equal(depth == 1.0, kinds == KIND_BACKGROUND), setup
    assert (kinds == KIND_BACKGROUND).any() and (kinds == KIND_PROBE).any()
    if setup == "planes":
        assert (kinds == KIND_CAP).any()
    if setup == "cube":
        assert (kinds == KIND_BACKBONE).any()


def test_drawn_passes_equal_their_compute_passes_to_the_bit(frame):
    """On the renderer's G-buffer the shadows, the analytic AO and the atlas lookup are drawn
    over the pixels the depth test picks; their compute programs run every pixel of the same
    G-buffer (without its depth): the shadows whole and over a rectangle, the AO with the
    probe, the atlas's accessibility and both lights' channels with the probe's share."""
    setup, scene, renderer, g = frame
    lighting = renderer.lighting
    drawn = GBuffer.of_targets(renderer.targets)
    computed = replace(drawn, depth=None)
    rect = (SIZE[0] // 4, SIZE[1] // 3, SIZE[0] // 2, SIZE[1] // 2)
    x, y, w, h = rect
    for light in lighting.lights:
        whole = [read_texture(lighting.shadows.trace(gb, light)) for gb in (drawn, computed)]
        assert np.array_equal(whole[0], whole[1]), (setup, light)
        assert (whole[0] < 0.5).any() and (whole[0] == 1.0).any()
        parts = []
        for gb in (drawn, computed):
            out = texture_2d(
                renderer.ctx, *SIZE, data=np.full(SIZE[::-1], 0.25, dtype=np.float32).tobytes()
            )
            parts.append(read_texture(lighting.shadows.trace(gb, light, out=out, rect=rect)))
            out.release()
        inside = np.zeros(SIZE[::-1], dtype=bool)
        inside[y : y + h, x : x + w] = True  # rows from the bottom, as the textures are
        assert np.array_equal(parts[0][inside], parts[1][inside]), (setup, light)
        assert np.array_equal(parts[0][inside], whole[0][inside])
        assert np.all(
            parts[0][~inside] == 0.25
        )  # (the compute pass rounds the rectangle up to its work groups)
    analytic = lighting.ao.program("analytic")
    ao = [
        read_texture(analytic.compute(gb, 16, out=texture_2d(renderer.ctx, *SIZE)))
        for gb in (drawn, computed)
    ]
    assert np.array_equal(ao[0], ao[1]) and (ao[0] < 0.6).any()
    atlas = OcclusionAtlas(lighting.grid)
    sun, lamp = lighting.lights
    try:
        atlas.update(8, 32, 8.0, True, sun.unit(), lamp)
        looked = [
            [read_texture(t) for t in atlas.lookup(gb, True, sun.unit(), lamp)]
            for gb in (drawn, computed)
        ]
    finally:
        atlas.release()
    for one, other in zip(*looked):
        assert np.array_equal(one, other), setup
        assert (one < 0.5).any() and (one == 1.0).any()


@pytest.mark.parametrize("cache", [True, False], ids=["layered", "whole"])
def test_visibility_buffer_carries_the_terms_to_the_shading_pass(gl, crambin, cache):
    """The shading pass's inputs hold the terms: the probe light's rays it is handed to trace
    (test_the_shading_pass_traces_the_probe_light_as_the_shadow_pass_does), and the
    visibility buffer's sun and ambient — on whole frames the terms as
    traced; on layered frames (the frame cache) the molecule's own, to which the shading
    pass adds the probe's share (its shadow of the sun, its analytic occlusion), so that
    with the share taken in on the CPU they are the exported terms. On layered frames the
    probe's own pixels keep the molecule's terms: the shading pass colours them without
    (test_render_frame_cache.py compares those pictures with whole frames)."""
    scene = make_scene(crambin, "planes")
    renderer, _ = render_lit(gl, scene, cache)
    g = gbuffer_arrays(renderer)
    t = renderer.targets
    vis = t.read(t.visibility).astype(np.float64)
    handed = renderer.last_frame.probe_lighting
    assert (
        handed.visibility is None and handed.traced is not None
    )  # the shading pass traces the probe light
    sun, ambient = vis[..., 0], vis[..., 2]
    if cache:
        ids = shaded_ids(g)
        atoms = ids >= 0
        probe = np.array([*scene.probe.center, scene.probe.radius])
        probe_only = Occluders(np.zeros((0, 3)), np.zeros(0), probe=probe)
        probe_sun = light_visibility(
            g["position"],
            g["normal"],
            ids,
            DirectionalLight(tuple(-g["light_direction"])),
            probe_only,
        )
        probe_ambient = 1.0 - probe_occlusion(
            g["position"], g["normal"], probe, renderer.pass_named("shading").settings.probe_range
        )
        assert (probe_sun[atoms] == 0).any() and (
            probe_ambient[atoms] < 0.99
        ).any()  # the share matters here
        sun = np.where(atoms, np.minimum(sun, probe_sun), sun)
        ambient = np.where(atoms, ambient * probe_ambient, ambient)
    compared = away_from_boundaries(g["shadow_dir"] < 0.5, shaded_ids(g) != -1) | (
        shaded_ids(g) == -1
    )
    terms_kept = g["atom_id"] != ATOM_PROBE if cache else np.ones(sun.shape, dtype=bool)
    assert np.abs(sun - g["shadow_dir"])[compared & terms_kept].max() <= 1e-3
    assert np.abs(ambient - g["ao"])[terms_kept].max() <= 2e-3
    assert np.all(vis[..., 1] == 1.0)  # the probe light's visibility has its own texture
    assert np.all(vis[..., 3] == 1.0)  # edge cueing off
    renderer.release()


@pytest.mark.parametrize("setup", SETUPS)
@pytest.mark.parametrize("cache", [False, True], ids=["whole", "layered"])
def test_the_shading_pass_traces_the_probe_light_as_the_shadow_pass_does(gl, crambin, setup, cache):
    """The shading pass traces the probe light's shadow rays itself (shaders/shading_traced.frag):
    its picture is the one it shades from the shadow pass's visibility texture of the same
    light (the export's, whose CPU reference is test_renderer_terms_match_the_cpu_references),
    bit for bit, with clip planes and a cube too, on whole and layered frames."""
    renderer, frame = render_lit(gl, make_scene(crambin, setup), cache)
    t, shading = renderer.targets, renderer.pass_named("shading")

    def shaded(
        probe_lighting,
    ) -> np.ndarray:  # the lit picture before the later passes draw over it
        shading.run(replace(frame, probe_lighting=probe_lighting))
        return t.read(t.lit)

    try:
        g = gbuffer_arrays(renderer)  # the export traces the probe light into a texture of its own
        atoms = shaded_ids(g) >= 0
        assert (g["shadow_probe"][atoms] < 0.5).any() and (
            g["shadow_probe"][atoms] > 0.5
        ).any()  # both occur
        traced = shaded(frame.probe_lighting)
        lamp = renderer.lighting.exported_terms["shadow_probe"]
        assert np.array_equal(
            traced, shaded(replace(frame.probe_lighting, visibility=lamp, traced=None))
        )
        assert not np.array_equal(
            traced, shaded(replace(frame.probe_lighting, traced=None))
        )  # its shadows show
    finally:
        renderer.release()


def test_edge_cueing_reaches_the_visibility_alpha(gl, crambin):
    scene = make_scene(crambin, "none")
    renderer, g = render_frame(
        gl, scene, LightingSettings(shadows="off", ao=AOSettings(mode="off"), edges="both")
    )
    t = renderer.targets
    alpha = t.read(t.visibility)[..., 3].astype(np.float32)
    ids = shaded_ids(g)
    cpu = edge_cueing(
        view_depths(g["position"], ids, g["view"]),
        ids,
        LightingSettings(edges="both").edge_settings(),
    )
    assert np.abs(alpha - cpu).max() < 2e-3
    assert (cpu < 0.5).sum() > 100
    assert "shadow_dir" not in g and "ao" not in g  # only what was computed is exported
    renderer.release()


def test_path_tracing_replaces_the_lit_atoms(gl, crambin):
    scene = make_scene(crambin, "planes")
    settings = LightingSettings(
        ao=AOSettings(mode="off"), shadows="off", path_tracing=True, samples=8
    )
    renderer, g = render_frame(gl, scene, settings)
    t = renderer.targets
    lit = t.read(t.lit)[..., :3].astype(np.float64) / 255
    tracer = renderer.lighting.tracer
    assert tracer.samples >= 8
    radiance = tracer.accumulated.read()
    radiance = np.frombuffer(radiance, dtype=np.float32).reshape(SIZE[1], SIZE[0], 4)[::-1, :, :3]
    shaded = shaded_ids(g) != -1
    assert np.abs(lit[shaded] - np.minimum(radiance[shaded], 1.0)).max() <= 1.0 / 255 + 1e-6
    # a still view keeps accumulating; a moved one starts over
    renderer.render(renderer.last_frame.camera)
    assert tracer.samples > 8
    camera = renderer.last_frame.camera
    camera.orbit(np.array([0.0, 1.0, 0.0]), 0.2)
    renderer.render(camera)
    assert tracer.samples == 8  # restarted, then brought to --samples again
    renderer.release()


def test_no_opengl_43_is_one_clear_line(crambin):
    class OldDriver:  # a GL 4.1 context as macOS offers (the renderer itself needs only 4.1)
        version_code = 410
        info = {"GL_RENDERER": "Apple M1", "GL_VERSION": "4.1 Metal"}

    with pytest.raises(GLUnavailable, match="need OpenGL 4.3.*Apple M1 offers 4.1 Metal"):
        LightingPass(OldDriver(), LightingSettings(), None)


def test_render_cli_takes_every_lighting_option(tmp_path):
    runs = [
        (ao, shadows) for ao, shadows in zip(AO_MODES, ["off", "hard", "soft", "precomputed"] * 2)
    ]
    for ao, shadows in runs:
        npz, png = tmp_path / f"{ao}.npz", tmp_path / f"{ao}.png"
        r = run_cli(
            "render",
            "--headless",
            "--size",
            "96x72",
            "--ao",
            ao,
            "--shadows",
            shadows,
            "--probe",
            "14,14,14",
            "--samples",
            "16",
            "--edges",
            "lines",
            "--out",
            str(png),
            "--gbuffer",
            str(npz),
            timeout=180,
        )
        assert r.returncode == 0, (ao, shadows, r.stderr)
        g = np.load(npz)
        assert iio.imread(png).shape[:2] == (72, 96)
        assert ("ao" in g.files) == (ao != "off")
        assert ("shadow_dir" in g.files) == ("shadow_probe" in g.files) == (shadows != "off")
        for layer in ("ao", "shadow_dir", "shadow_probe"):
            if layer in g.files:
                values = g[layer]
                assert values.dtype == np.float32 and values.shape == (72, 96)
                assert values.min() >= 0.0 and values.max() <= 1.0
                assert values[g["atom_id"] >= 0].min() < 0.9, (
                    ao,
                    shadows,
                    layer,
                )  # something is occluded
        np.testing.assert_allclose(g["probe_light"], [14, 14, 14, 20])
    r = run_cli(
        "render",
        "--headless",
        "--size",
        "64x48",
        "--path-trace",
        "--samples",
        "4",
        "--ao",
        "off",
        "--out",
        str(tmp_path / "pt.png"),
        timeout=180,
    )
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize(
    "args, words",
    [
        (["--ao", "magic"], ["--ao", "magic"]),
        (["--soft-shell", "0,3"], ["--soft-shell", "probe radius"]),
        (["--soft-shell", "1,0"], ["--soft-shell"]),
        (["--pt-bounces", "7"], ["--pt-bounces"]),
    ],
)
def test_bad_lighting_options_are_one_line(args, words):
    r = run_cli("render", "--headless", "--size", "32x32", *args)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sasprobe"), r.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_window_keys_switch_the_lighting(xvfb):
    """In a real window (Xvfb; its own process, as GLX and this process's EGL context do
    not mix): S, V, A, E, G switch the effects, C cycles the AO method, and what the
    window draws changes with them (tests/window_scripts/lighting.py)."""
    run_window_check(xvfb, "tests.window_scripts.lighting")
