"""The shading pass against a numpy Phong reference (including the visibility factors a
lighting pass slots in), the toggles, the touched-atom highlight, and FXAA."""

from __future__ import annotations

import numpy as np
import pytest
from sasprobe.render.camera import Camera
from sasprobe.render.gbuffer_export import gbuffer_arrays
from sasprobe.render.gl.targets import KIND_BACKGROUND, KIND_PROBE
from sasprobe.render.gl.textures import release_framebuffers
from sasprobe.render.passes.base import Pass, ProbeLighting
from sasprobe.render.passes.probe import PROBE_COLOR
from sasprobe.render.renderer import Renderer
from sasprobe.render.scene_state import Probe, SceneState

from tests.support.render import edge_mask

SIZE = (160, 120)
TOL = 2.5 / 255  # RGBA8 rounding plus float32 shading


class FixedVisibility(Pass):
    """Stands in for a shadow/AO pass: writes given visibility factors before the shading
    pass, the probe light's (channel 1) as the texture the lighting hands over."""

    name = "fixed_visibility"

    def __init__(self, values: np.ndarray):
        self.values = values  # (H, W, 4) float, row 0 = top
        self.probe_light = None

    def run(self, frame) -> None:
        rows_up = self.values[::-1]
        frame.targets.visibility.write(np.ascontiguousarray(rows_up, dtype=np.float32).tobytes())
        if self.probe_light is None:
            self.probe_light = frame.ctx.texture(frame.size, 1, dtype="f4")
        self.probe_light.write(np.ascontiguousarray(rows_up[..., 1], dtype=np.float32).tobytes())
        frame.probe_lighting = ProbeLighting(self.probe_light)

    def release(self) -> None:
        if self.probe_light is not None:
            self.probe_light.release()


def scene_with_probe(s):
    atom = 200
    probe = Probe(
        center=s.positions[atom]
        + np.array([0.0, 0.3, 1.0]) / np.linalg.norm([0.0, 0.3, 1.0]) * (s.vdw_radii[atom] + 1.4),
        touched_atom=atom,
    )
    return SceneState(s, probe=probe), atom


def render(gl, scene, camera, extra_pass=None):
    renderer = Renderer(gl, scene, SIZE)
    renderer.passes.remove(
        renderer.pass_named("probe_cues")
    )  # drawn over the lit image: not the shading's
    if extra_pass is not None:
        renderer.insert_before("shading", extra_pass)
    try:
        renderer.render(camera)
        t = renderer.targets
        lit = t.read(t.lit)[..., :3] / 255.0
        albedo = t.read(t.albedo)[..., :3] / 255.0
        final = renderer.read_image() / 255.0
        return gbuffer_arrays(renderer), lit, albedo, final, renderer.pass_named("shading").settings
    finally:
        renderer.release()


def phong(albedo, n, v, light, s):
    """Phong's diffuse and specular terms; `light` points toward the light."""
    diffuse = np.clip(np.einsum("...i,...i", n, light), 0, None)
    r = -light - 2 * np.einsum("...i,...i", n, -light)[..., None] * n  # reflect(-light, n)
    spec = np.where(diffuse > 0, np.clip(np.einsum("...i,...i", r, v), 0, None) ** s.shininess, 0.0)
    return diffuse[..., None] * albedo + spec[..., None] * s.specular


def reference_light(g, albedo, scene, camera, s, vis):
    p, n = g["position"].astype(np.float64), g["normal"].astype(np.float64)
    n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    v = camera.eye - p
    v /= np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)
    fx = scene.effects
    if fx.highlight and scene.probe is not None and scene.probe.touched_atom >= 0:
        touched = (g["atom_id"] == scene.probe.touched_atom) & (g["kind"] != 3)
        albedo = albedo.copy()
        albedo[touched] = 0.4 * albedo[touched] + 0.6 * np.array(s.highlight)
    color = s.ambient * vis[..., 2:3] ** s.ao_power * albedo
    if fx.directional_light:
        color += (
            vis[..., 0:1] * s.directional_intensity * phong(albedo, n, v, -scene.light_direction, s)
        )
    if fx.probe_light and scene.probe is not None:
        to_probe = scene.probe.center - p
        dist = np.linalg.norm(to_probe, axis=-1, keepdims=True)
        c0, c1, c2 = s.probe_attenuation
        window = np.clip(1.0 - (dist / s.probe_range) ** 4, 0.0, 1.0) ** 2
        atten = window / (c0 + c1 * dist + c2 * dist**2)
        atoms = (g["kind"] != 3)[
            ..., None
        ]  # the backbone trace is context: the probe does not light it
        color += (
            atoms
            * vis[..., 1:2]
            * s.probe_intensity
            * atten
            * phong(albedo, n, v, to_probe / dist, s)
        )
    color = np.minimum(color, 1.0)
    probe_px = g["kind"] == KIND_PROBE
    color[probe_px] = (
        np.array(PROBE_COLOR)
        * (0.75 + 0.25 * np.clip(np.einsum("...i,...i", n, v), 0, None))[probe_px, None]
    )
    color[g["kind"] == KIND_BACKGROUND] = s.background
    return color * vis[..., 3:4]  # edge cueing scales everything


def test_shading_pass_matches_phong_reference_with_visibility_factors(gl, crambin):
    scene, atom = scene_with_probe(crambin)
    camera = Camera(
        eye=scene.probe.center + np.array([4.0, 6.0, 22.0]), target=scene.probe.center, fov_y=50.0
    )
    rng = np.random.default_rng(3)
    vis = rng.uniform(0.0, 1.0, size=(SIZE[1], SIZE[0], 4)).astype(np.float32).astype(np.float64)
    g, lit, albedo, _, settings = render(gl, scene, camera, FixedVisibility(vis))
    assert (g["kind"] == KIND_PROBE).sum() > 100
    expected = reference_light(g, albedo, scene, camera, settings, vis)
    assert np.abs(lit - expected).max() <= TOL
    # The visibility factors really matter: the same frame without them differs.
    g1, lit1, *_ = render(gl, scene, camera)
    assert np.abs(lit1 - lit)[g1["kind"] == 1].mean() > 0.05


@pytest.mark.parametrize("switch", ["directional_light", "probe_light"])
def test_each_light_can_be_switched_off(gl, crambin, switch):
    scene, _ = scene_with_probe(crambin)
    setattr(scene.effects, switch, False)
    camera = Camera(
        eye=scene.probe.center + np.array([4.0, 6.0, 22.0]), target=scene.probe.center, fov_y=50.0
    )
    g, lit, albedo, _, settings = render(gl, scene, camera)
    ones = np.ones((SIZE[1], SIZE[0], 4))
    assert np.abs(lit - reference_light(g, albedo, scene, camera, settings, ones)).max() <= TOL
    setattr(scene.effects, switch, True)
    g2, lit2, *_ = render(gl, scene, camera)
    assert np.abs(lit2 - lit)[g2["kind"] == 1].mean() > 0.01


def test_touched_atom_is_highlighted(gl, crambin):
    scene, atom = scene_with_probe(crambin)
    scene.effects.probe = False  # so the touched atom is not hidden behind the probe
    camera = Camera(
        eye=scene.probe.center + np.array([4.0, 6.0, 22.0]), target=scene.probe.center, fov_y=50.0
    )
    first, *_ = render(gl, scene, camera)
    ids, counts = np.unique(first["atom_id"][first["atom_id"] >= 0], return_counts=True)
    atom = scene.probe.touched_atom = int(ids[np.argmax(counts)])  # the atom most in view
    g, lit, albedo, _, settings = render(gl, scene, camera)
    mine = g["atom_id"] == atom
    assert mine.sum() > 50
    np.testing.assert_allclose(
        albedo[mine], np.broadcast_to(crambin.colors[atom], albedo[mine].shape), atol=TOL
    )
    ones = np.ones((SIZE[1], SIZE[0], 4))
    assert np.abs(lit - reference_light(g, albedo, scene, camera, settings, ones)).max() <= TOL
    scene.effects.highlight = False
    g2, plain, *_ = render(gl, scene, camera)
    assert np.abs(plain - reference_light(g2, albedo, scene, camera, settings, ones)).max() <= TOL
    # Highlighted: the atom's pixels move towards the highlight colour (mint: green up, red down).
    shift = (lit[mine] - plain[mine]).mean(axis=0)
    assert shift[1] > 0.05 and shift[0] < 0


def test_fxaa_only_softens_edges(gl, crambin):
    scene = SceneState(crambin)
    center, radius = scene.bounding_sphere()
    camera = Camera.fitted(center, radius, SIZE[0] / SIZE[1])
    g, lit, _, final, _ = render(gl, scene, camera)
    changed = np.abs(final - lit).max(axis=2) > 1.5 / 255
    assert changed.sum() > 100, "FXAA should touch the silhouettes"
    # Only where the luma has contrast with a diagonal neighbour (FXAA's own edge test).
    luma = lit @ np.array([0.299, 0.587, 0.114])
    pad = np.pad(luma, 1, mode="edge")
    diag = [pad[:-2, :-2], pad[:-2, 2:], pad[2:, :-2], pad[2:, 2:], luma]
    contrast = np.max(diag, axis=0) - np.min(diag, axis=0)
    assert np.all(contrast[changed] >= 0.0312 - 1e-3)
    # Flat interiors and the background stay exactly as lit.
    flat = ~edge_mask(g["atom_id"]) & (contrast < 0.02)
    assert np.abs(final - lit)[flat].max() <= 1.5 / 255
    scene.effects.fxaa = False
    _, lit2, _, final2, _ = render(gl, scene, camera)
    assert np.abs(final2 - lit2).max() <= 1 / 255


def test_near_surface_mask_is_the_surfaces_grown_by_fxaas_reach(gl, crambin):
    """The FXAA pass's mask (NearSurfaces) marks exactly the pixels within FXAA_REACH_PX
    (Chebyshev distance) of a pixel that is not background, against a box dilation of the
    G-buffer's kinds on the CPU; the molecule lies amid the background, so both occur."""
    from sasprobe.render.passes.fxaa import FXAA_REACH_PX, NearSurfaces

    size = (160, 120)
    scene = SceneState(crambin)
    renderer = Renderer(gl, scene, size)
    c, r = scene.bounding_sphere()
    frame = renderer.render(Camera.fitted(c, r * 1.6, size[0] / size[1]))
    near = NearSurfaces(gl, renderer.programs)
    try:
        mask = (
            np.frombuffer(near.get(frame).read(), dtype=np.float32).reshape(size[1], size[0]) < 0.5
        )
        surface = (
            renderer.targets.read(renderer.targets.ids)[::-1, :, 1] != KIND_BACKGROUND
        )  # row 0 = bottom
        reach = FXAA_REACH_PX
        padded = np.pad(surface, reach)
        expected = np.zeros_like(surface)
        for dy in range(2 * reach + 1):
            for dx in range(2 * reach + 1):
                expected |= padded[dy : dy + size[1], dx : dx + size[0]]
        assert 0.1 < expected.mean() < 0.9
        assert np.array_equal(mask, expected)
    finally:
        near.release()
        renderer.release()


def test_fxaa_reads_no_further_than_its_reach(gl):
    """FXAA_REACH_PX, what the frame cache grows a changed rectangle by before running FXAA
    again there, holds the shader: on a high-contrast random picture, changing one pixel
    changes the output only within that many pixels of it (and the reach is not far above
    what the shader reads)."""
    from types import SimpleNamespace

    from sasprobe.render.frame_planner import FramePlan
    from sasprobe.render.gl.programs import ProgramCache
    from sasprobe.render.gl.textures import read_image
    from sasprobe.render.passes.fxaa import FXAA_REACH_PX, FxaaPass

    size = (64, 64)
    rng = np.random.default_rng(7)
    picture = (rng.random((size[1], size[0], 4)) > 0.5).astype(np.uint8) * 255
    lit, out = gl.texture(size, 4), gl.texture(size, 4)
    lit_fbo, out_fbo = gl.framebuffer([lit]), gl.framebuffer([out])
    programs = ProgramCache(gl)
    fxaa = FxaaPass(gl, programs)
    frame = SimpleNamespace(
        ctx=gl,
        targets=SimpleNamespace(lit=lit, lit_fbo=lit_fbo),
        size=size,
        plan=FramePlan(size=size),
        output_fbo=out_fbo,
        scene=SimpleNamespace(effects=SimpleNamespace(fxaa=True)),
    )

    def antialiased(image: np.ndarray) -> np.ndarray:
        lit.write(np.ascontiguousarray(image[::-1]).tobytes())
        fxaa.run(frame)
        return read_image(out_fbo, size).astype(int)

    try:
        before = antialiased(picture)
        farthest = 0
        for y, x in rng.integers(16, 48, size=(24, 2)):
            changed = picture.copy()
            changed[y, x, :3] = 255 - changed[y, x, :3]
            rows, cols = np.nonzero(np.abs(antialiased(changed) - before).max(axis=2))
            assert rows.size  # the pixel itself, at least
            farthest = max(farthest, int(np.max(np.maximum(np.abs(rows - y), np.abs(cols - x)))))
        assert FXAA_REACH_PX - 3 <= farthest <= FXAA_REACH_PX, farthest
    finally:
        fxaa.release()
        programs.release()
        release_framebuffers(gl, lit_fbo, out_fbo)
        lit.release()
        out.release()


def test_a_depth_tested_target_follows_its_textures(gl):
    """DepthTestedTarget keeps a framebuffer per (colour, depth) pair: the same textures
    give the same one, and a texture made after another's release (which may get its GL
    name) gets a framebuffer of its own that draws into it, tests against the depth and
    does not write it."""
    from sasprobe.render.gl.depth_picked import DepthTestedTarget

    target = DepthTestedTarget(gl)
    depth = gl.depth_texture((8, 4))
    first = gl.texture((8, 4), 4, dtype="f1")
    fbo = target.framebuffer(first, depth)
    assert target.framebuffer(first, depth) is fbo
    first.release()
    second = gl.texture((8, 4), 4, dtype="f1")
    other = target.framebuffer(second, depth)
    assert (
        other is not fbo
        and other.color_attachments[0] is second
        and other.depth_attachment is depth
    )
    assert other.depth_mask is False
    target.release()
    second.release()
    depth.release()
