"""QuteMol's precomputed occlusion (render/lighting/ao/precomputed.py) against its CPU
reference (tests/references/atlas.py): the baked patches, the fill of texels inside other
atoms, the per-pixel lookup, caps, when it bakes again, and how close it comes to the
converged ray-traced AO and the exact per-pixel shadow."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from sasprobe.render.gl.targets import KIND_CAP
from sasprobe.render.gl.textures import read_texture
from sasprobe.render.lighting.ao import AmbientOcclusion
from sasprobe.render.lighting.ao.atlas_tables import (
    clustered,
    facing_masks,
    fibonacci_directions,
    texel_normals,
)
from sasprobe.render.lighting.ao.precomputed import OcclusionAtlas
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.settings import (
    HARD_SHADOW,
    AOSettings,
    DirectionalLight,
    LightingSettings,
    PointLight,
)

from tests.references.atlas import bake_atom, bilinear, fill_hidden, octa_decode, octa_encode
from tests.references.lighting import Occluders, light_visibility
from tests.support.lighting import away_from_boundaries, camera, cullings, gbuffer_arrays

pytestmark = pytest.mark.needs_gl(430)

SUN = np.array([0.45, 0.8, 0.4]) / np.linalg.norm([0.45, 0.8, 0.4])  # towards the light
PATCH, DIRECTIONS, DISTANCE = 5, 24, 8.0


def patch_of(atlas: OcclusionAtlas, values: np.ndarray, atom: int) -> np.ndarray:
    slot = int(atlas.slot_of()[atom])
    x, y = (slot % atlas.tiles_x) * atlas.patch, (slot // atlas.tiles_x) * atlas.patch
    return values[y : y + atlas.patch, x : x + atlas.patch]


def test_octahedral_reference_round_trips():
    v = np.random.default_rng(1).normal(size=(500, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    assert np.abs(octa_decode(octa_encode(v)) - v).max() < 1e-12


def test_directions_are_clustered_without_changing_the_set():
    d = fibonacci_directions(64)
    c = clustered(d)
    assert (
        np.array_equal(np.sort(c, axis=0), np.sort(d, axis=0)) and len(np.unique(c, axis=0)) == 64
    )

    def spread(v):  # mean angle of a group of 8 from its mean direction
        g = v.reshape(-1, 8, 3)
        m = g.mean(axis=1, keepdims=True) / np.linalg.norm(
            g.mean(axis=1, keepdims=True), axis=2, keepdims=True
        )
        return np.degrees(np.arccos(np.clip((g * m).sum(axis=2), -1, 1))).mean()

    assert spread(c) < 0.5 * spread(d)  # the lattice's own order spreads each 8 around a band


@pytest.mark.parametrize("patch, directions", [(5, 24), (8, 64), (9, 40)])
def test_facing_bits_mark_exactly_the_texels_facing_each_direction(patch, directions):
    normals = texel_normals(patch)
    j, i = np.divmod(
        np.arange(patch * patch), patch
    )  # texel (i, j) at i + P j, centres on the border
    expected = octa_decode(np.column_stack([i, j]) * (2.0 / (patch - 1)) - 1.0)
    assert np.abs(normals[:, :3] - expected).max() < 1e-6
    d = clustered(fibonacci_directions(directions))
    by_direction, by_texel, weight = facing_masks(normals, d)
    faces = d @ normals[:, :3].T.astype(np.float64) > 0  # (D, P^2)

    def bit(words, row, k):  # bit k % 32 of word k / 32, read one at a time
        return (int(words[row, k // 32]) >> (k % 32)) & 1 == 1

    assert by_direction.shape == (directions, -(-patch * patch // 32)) and by_texel.shape == (
        patch * patch,
        -(-directions // 32),
    )
    for k in range(directions):
        for t in range(patch * patch):
            assert bit(by_direction, k, t) == bit(by_texel, t, k) == faces[k, t], (k, t)
    assert np.allclose(
        weight, np.where(faces, d @ normals[:, :3].T.astype(np.float64), 0.0).sum(axis=0)
    )
    spare = (
        by_direction.shape[1] * 32 - patch * patch
    )  # the last word's bits past the last texel are 0
    assert spare == 0 or not np.any(by_direction[:, -1] >> np.uint32(32 - spare))


@pytest.mark.parametrize(
    "setup, patch",
    [("none", PATCH), ("plane", PATCH), ("cube", PATCH), ("plane", 8), ("none", 9), ("cube", 9)],
)
def test_patches_equal_the_cpu_bake(gl, crambin, crambin_grid, setup, patch):
    """Patch 5 fits its texels' bits in one word, patch 8 (the default) in two: the rays step
    takes both at once; patch 9 spreads them over three, taken as a stream of words."""
    crambin_grid.set_culling(cullings(crambin)[setup])
    occ = Occluders.of(crambin_grid)
    atlas = OcclusionAtlas(crambin_grid)
    try:
        lamp = PointLight(tuple(crambin.positions[40] + [0.0, 0.0, 3.5]), 12.0)
        assert atlas.update(
            patch, DIRECTIONS, DISTANCE, ambient=True, sun_direction=SUN, probe_light=lamp
        )
        values = atlas.read()
        kept = np.flatnonzero(~crambin_grid.culled_mask)
        assert atlas.n_slots == kept.size and np.array_equal(
            np.flatnonzero(atlas.slot_of() >= 0), kept
        )
        rng = np.random.default_rng(5)
        close = seen = partly_seen = 0
        for atom in rng.choice(kept, size=min(24, kept.size), replace=False):
            ambient, sun, light, hidden = bake_atom(
                int(atom), occ, patch, DIRECTIONS, DISTANCE, SUN, (lamp.position, lamp.radius)
            )
            gpu = patch_of(atlas, values, int(atom))
            for channel, cpu in ((0, ambient), (1, sun), (2, light)):
                filled = fill_hidden(cpu, hidden)
                ok = np.abs(gpu[..., channel] - filled) <= 2e-3  # float16 storage
                close += ok.sum()
                seen += ok.size
            assert hidden.any()  # bonded neighbours hide part of every atom
            partly_seen += not hidden.all()  # (an atom the culling cuts may be hidden whole)
        assert close / seen >= 0.98, close / seen  # a ray grazing a sphere may go either way
        assert partly_seen >= 18
    finally:
        atlas.release()
        crambin_grid.set_culling(Culling())


def test_the_atlas_does_not_depend_on_how_the_atoms_are_chunked(gl, crambin_grid, monkeypatch):
    """Bakes of many directions or large patches go in smaller chunks, so their storage stays
    bounded (MAX_SCRATCH_BYTES); chunks of a few dozen atoms give the one chunk's atlas."""
    from sasprobe.render.lighting.ao import precomputed

    crambin_grid.set_culling(Culling())
    atlases = []
    try:
        for budget, one_chunk in (
            (precomputed.MAX_SCRATCH_BYTES, True),
            (2 * 2**20, False),
        ):  # 2 MiB: ~50 atoms
            monkeypatch.setattr(precomputed, "MAX_SCRATCH_BYTES", budget)
            atlas = OcclusionAtlas(crambin_grid)
            atlases.append(atlas)
            chunks = []
            assert atlas.update(
                PATCH, 256, DISTANCE, ambient=True, sun_direction=SUN, progress=chunks.append
            )
            assert (len(chunks) == 1) == one_chunk and chunks[-1] == 1.0, chunks
        assert np.array_equal(atlases[0].read(), atlases[1].read())
    finally:
        for atlas in atlases:
            atlas.release()


def assert_lookup_reads_the_patches(crambin, grid, patch: int) -> None:
    """Each sphere pixel reads its atom's patch bilinearly in the octahedral direction of its
    point; caps are open (accessibility 1, lit where they face the light)."""
    view, proj = camera(crambin)
    gbuffer, pos, nrm, atom = gbuffer_arrays(grid, view, proj)
    atlas = OcclusionAtlas(grid)
    try:
        atlas.update(patch, DIRECTIONS, DISTANCE, ambient=True, sun_direction=SUN)
        ambient_tex, sun_tex, _ = atlas.lookup(gbuffer, True, SUN)
        ambient, sun = read_texture(ambient_tex), read_texture(sun_tex)
        values, slots = atlas.read(), atlas.slot_of()
        kinds = gbuffer.kinds()
        caps = kinds == KIND_CAP
        assert caps.sum() > 50
        assert np.all(ambient[caps] == 1.0)
        assert np.array_equal(sun[caps] == 1.0, (nrm[caps] @ SUN) > 0)
        spheres = (atom >= 0) & ~caps
        ys, xs = np.nonzero(spheres)
        good = 0
        for y, x in zip(ys, xs):
            a = atom[y, x]
            slot = slots[a]
            e = octa_encode(
                (pos[y, x] - crambin.positions[a])
                / np.linalg.norm(pos[y, x] - crambin.positions[a])
            )
            tx, ty = (slot % atlas.tiles_x) * patch, (slot // atlas.tiles_x) * patch
            u = tx + (e[0] * 0.5 + 0.5) * (patch - 1) + 0.5
            v = ty + (e[1] * 0.5 + 0.5) * (patch - 1) + 0.5
            expected = bilinear(values, u, v)
            good += np.abs(expected[:2] - np.array([ambient[y, x], sun[y, x]])).max() <= 1e-2
        assert good / len(ys) >= 0.995
        assert np.all(ambient[atom == -1] == 1.0)
    finally:
        atlas.release()
        gbuffer.release()


def test_lookup_is_the_bilinear_patch_value_and_caps_are_open(gl, crambin, crambin_grid):
    crambin_grid.set_culling(cullings(crambin)["plane"])
    try:
        assert_lookup_reads_the_patches(crambin, crambin_grid, PATCH)
    finally:
        crambin_grid.set_culling(Culling())


def test_an_atlas_of_power_of_two_sides_is_padded_and_reads_the_same(gl, crambin, crambin_grid):
    """llvmpipe compiles a shader variant per power-of-two-ness of a texture's sides, so the
    atlas never takes such a side (gl/textures.py steady_side): 57-64 patches of 8 texels,
    8 tiles each way, make a 64x64 atlas, which takes a texel more each way and is read as
    before."""
    centre = crambin.positions.mean(axis=0)
    try:
        for half in np.arange(1.0, 10.0, 0.05):  # a cube that keeps 57-64 atoms
            crambin_grid.set_culling(Culling(nav_cube=(centre, float(half))))
            if 57 <= (~crambin_grid.culled_mask).sum() <= 64:
                break
        else:
            pytest.fail("no cube of crambin keeps 57-64 atoms")
        atlas = OcclusionAtlas(crambin_grid)
        try:
            atlas.update(8, DIRECTIONS, DISTANCE, ambient=True)
            assert atlas.tiles_x == 8 and atlas.texture.size == (65, 65)
        finally:
            atlas.release()
        assert_lookup_reads_the_patches(crambin, crambin_grid, 8)
    finally:
        crambin_grid.set_culling(Culling())


def test_it_bakes_once_per_culling_and_light(gl, crambin, crambin_grid):
    atlas = OcclusionAtlas(crambin_grid)
    try:
        crambin_grid.set_culling(Culling())
        assert atlas.update(PATCH, DIRECTIONS, DISTANCE, ambient=True)
        assert not atlas.update(PATCH, DIRECTIONS, DISTANCE, ambient=True)
        assert atlas.update(
            PATCH, DIRECTIONS, DISTANCE, ambient=True, sun_direction=SUN
        )  # the light channel
        assert not atlas.update(PATCH, DIRECTIONS, DISTANCE, ambient=True, sun_direction=SUN)
        assert atlas.update(
            PATCH, DIRECTIONS, DISTANCE, ambient=True, sun_direction=-SUN
        )  # the light moved
        crambin_grid.set_culling(cullings(crambin)["cube"])
        assert atlas.update(PATCH, DIRECTIONS, DISTANCE, ambient=True)  # new culling: new patches
        assert atlas.n_slots == int((~crambin_grid.culled_mask).sum()) < crambin.n_atoms
        assert atlas.update(PATCH + 1, DIRECTIONS, DISTANCE, ambient=True)
        with pytest.raises(ValueError, match="--ao-patch"):
            atlas.update(
                4000, DIRECTIONS, DISTANCE, ambient=True
            )  # an atlas beyond the texture size
    finally:
        atlas.release()
        crambin_grid.set_culling(Culling())


def test_the_benchmark_times_a_bake_for_every_figure(gl, crambin, crambin_grid):
    """sasprobe bench lighting's bake times (bench/lighting_precomputed.py bake_seconds) each
    come from a bake that ran: both channels at a culling change, the accessibility alone,
    the light alone (a stale time, from an update that baked nothing, is an error there)."""
    from sasprobe.cli.bench.lighting_precomputed import bake_seconds

    settings = AOSettings(patch=PATCH, directions=DIRECTIONS, distance=DISTANCE)
    try:
        for culling, repeats in ((Culling(), 1), (cullings(crambin)["cube"], 2)):
            row = bake_seconds(crambin_grid, culling, settings, repeats=repeats)
            assert (
                row["patches"] == int((~crambin_grid.culled_mask).sum()) and row["bakes"] == repeats
            )
            assert min(row["total_s"], row["ambient_s"], row["sun_s"]) > 0 and row["overflows"] == 0
    finally:
        crambin_grid.set_culling(Culling())


def test_accuracy_against_the_converged_reference_and_the_exact_shadow(gl, crambin, crambin_grid):
    """At the default patch and directions the precomputed AO is closer to converged
    ray-traced AO than analytic AO with 32 neighbours, and its shadow agrees with the exact
    per-pixel one away from shadow boundaries."""
    crambin_grid.set_culling(Culling())
    view, proj = camera(crambin, 96, 72)
    gbuffer, pos, nrm, atom = gbuffer_arrays(crambin_grid, view, proj, 96, 72)
    ao = AmbientOcclusion(crambin_grid)
    try:
        base = AOSettings()
        ao.configure(replace(base, mode="reference", reference_spp=64, reference_total=256))
        while not ao.converged:
            reference = ao.compute(gbuffer, view, proj)
        reference = read_texture(reference).copy()
        errors = {}
        for mode in ("precomputed", "analytic"):
            ao.configure(replace(base, mode=mode))
            image = read_texture(ao.compute(gbuffer, view, proj))
            errors[mode] = float(np.sqrt(np.mean((image - reference)[atom >= 0] ** 2)))
        assert errors["precomputed"] < 0.7 * errors["analytic"], errors
        sun = read_texture(ao.baked(gbuffer, ambient=False, sun_direction=SUN)[1])
        exact = light_visibility(
            pos, nrm, atom, DirectionalLight(tuple(SUN)), Occluders.of(crambin_grid), HARD_SHADOW
        )
        valid = atom >= 0
        compared = away_from_boundaries(exact < 0.5, valid)
        assert ((sun >= 0.5) == (exact >= 0.5))[compared].mean() >= 0.95
    finally:
        ao.release()
        gbuffer.release()


def test_a_still_probe_lights_from_the_atlas_and_a_moving_one_is_traced(gl, crambin):
    """With --shadows precomputed the probe light's shadows come from the atlas once the probe
    has stood still a few frames (the camera may turn): they agree with the exact shadow off
    shadow boundaries, and only the patches within the light's range are baked for it; when
    the probe moves again they are traced per pixel."""
    from sasprobe.render.camera import Camera
    from sasprobe.render.gbuffer_export import gbuffer_arrays as export
    from sasprobe.render.passes.lighting import STILL_FRAMES
    from sasprobe.render.renderer import Renderer
    from sasprobe.render.scene_state import Probe, SceneState

    from tests.support.lighting import probe_on_surface

    settings = LightingSettings(shadows="precomputed", ao=AOSettings(mode="off"))
    scene = SceneState(crambin, probe=Probe(center=probe_on_surface(crambin, (0.2, 0.3, 1.0))))
    for name, on in settings.effects().items():
        setattr(scene.effects, name, on)
    renderer = Renderer(gl, scene, (128, 96))
    renderer.install_lighting(settings)
    center, radius = scene.bounding_sphere()
    camera = Camera.fitted(center, radius * 0.8, 128 / 96, direction=(0.2, 0.3, 1.0))
    try:
        atlas = None
        for k in range(STILL_FRAMES + 2):
            camera.orbit(np.array([0.0, 1.0, 0.0]), 0.02)
            renderer.render(camera)
            atlas = renderer.lighting.ao.program("atlas")
            assert (atlas.probe_key is not None) == (k >= STILL_FRAMES), k
            if k == STILL_FRAMES:
                assert 0 < atlas.baked_patches < atlas.n_slots  # the atoms within the light's range
        g = export(renderer)
        ids = np.where(g["kind"] == 3, -1, g["atom_id"])
        lamp = PointLight(tuple(g["probe_light"][:3]), float(g["probe_light"][3]))
        exact = light_visibility(
            g["position"],
            g["normal"],
            ids,
            lamp,
            Occluders(crambin.positions, crambin.vdw_radii),
            HARD_SHADOW,
        )
        atoms = ids >= 0
        compared = away_from_boundaries(exact < 0.5, atoms)
        agree = ((g["shadow_probe"] >= 0.5) == (exact >= 0.5))[compared].mean()
        assert agree >= 0.95  # measured 0.99
        assert (exact[atoms] < 0.5).mean() > 0.05  # there are probe-light shadows to get right
        baked_before = atlas.bake_seconds
        scene.probe = Probe(center=scene.probe.center + [0.4, 0.0, 0.0])
        renderer.render(camera)
        assert atlas.bake_seconds == baked_before  # moved: traced, not baked
        assert renderer.lighting._still_frames == 0
    finally:
        renderer.release()
