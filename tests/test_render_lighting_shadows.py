"""Shadows traced on the GPU through the grid against the numpy ray tester on the same
G-buffer positions (directional and probe light; hard and Parker soft; with and without
clipping and cube culling)."""

from __future__ import annotations

import numpy as np
import pytest
from sasprobe.molecule import DEFAULT_PROBE_RADIUS
from sasprobe.render.gl.textures import read_texture
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.light_buffer import cell_cones
from sasprobe.render.lighting.settings import (
    HARD_SHADOW,
    DirectionalLight,
    PointLight,
    SoftShadow,
    ray_epsilon,
)
from sasprobe.render.lighting.shadows import ShadowTracer

from tests.references.lighting import Occluders, light_visibility
from tests.support.lighting import (
    away_from_boundaries,
    camera,
    cullings,
    gbuffer_arrays,
    probe_on_surface,
    sphere_grid,
)

pytestmark = pytest.mark.needs_gl(430)  # compute shaders, storage buffers

SUN = DirectionalLight((0.45, 0.8, 0.4))


def probe_light(structure) -> PointLight:
    """The probe's light: the probe resting on the surface facing the camera."""
    return PointLight(tuple(probe_on_surface(structure)), 14.0)


@pytest.fixture(scope="module")
def shadow_pass(crambin_grid):
    p = ShadowTracer(crambin_grid)
    yield p
    p.release()


@pytest.fixture(scope="module", params=["none", "plane", "cube"])
def scene(request, crambin, crambin_grid):
    """Culling applied, the probe placed (it occludes the sun), a G-buffer traced."""
    crambin_grid.set_culling(cullings(crambin)[request.param])
    light = probe_light(crambin)
    crambin_grid.set_probe(np.asarray(light.position), DEFAULT_PROBE_RADIUS)
    view, proj = camera(crambin)
    gbuffer, position, normal, atom = gbuffer_arrays(crambin_grid, view, proj)
    yield request.param, gbuffer, position, normal, atom, Occluders.of(crambin_grid)
    gbuffer.release()
    crambin_grid.set_culling(Culling())
    crambin_grid.set_probe(None)


@pytest.mark.parametrize("light_kind", ["directional", "probe"])
def test_hard_shadows_equal_the_cpu_ray_tracer(crambin, shadow_pass, scene, light_kind):
    name, gbuffer, position, normal, atom, occluders = scene
    light = SUN if light_kind == "directional" else probe_light(crambin)
    gpu = read_texture(shadow_pass.trace(gbuffer, light, HARD_SHADOW))
    cpu = light_visibility(position, normal, atom, light, occluders, HARD_SHADOW)
    valid = atom != -1
    assert set(np.unique(gpu[valid])) <= {0.0, 1.0}
    shadowed = cpu < 0.5
    # a scene worth testing: both classes present in quantity among the traced pixels
    traced = (
        valid
        if light_kind == "directional"
        else valid
        & (np.linalg.norm(position - np.asarray(light.position), axis=-1) <= light.radius)
    )
    assert traced.sum() > 500 and 0.1 < shadowed[traced].mean() < 0.9, (
        name,
        shadowed[traced].mean(),
    )
    compared = away_from_boundaries(shadowed, valid)
    assert compared.sum() > 0.6 * valid.sum()
    agreement = ((gpu < 0.5) == shadowed)[compared].mean()
    assert agreement >= 0.995, (name, light_kind, agreement)
    assert np.all(gpu[~valid] == 1.0)


def test_probe_light_is_limited_to_its_radius(crambin, shadow_pass, scene):
    _, gbuffer, position, normal, atom, _ = scene
    light = probe_light(crambin)
    gpu = read_texture(shadow_pass.trace(gbuffer, light, HARD_SHADOW))
    far = (atom != -1) & (
        np.linalg.norm(position - np.asarray(light.position), axis=-1) > light.radius + 1e-3
    )
    assert far.sum() > 100 and np.all(
        gpu[far] == 1.0
    )  # not traced: unlit by attenuation, not shadow


def test_soft_shadows_match_the_cpu_parker_reference(crambin, shadow_pass, scene):
    name, gbuffer, position, normal, atom, occluders = scene
    soft = SoftShadow(inner=-0.4, outer=1.0, growth=4.0)
    for light in (SUN, probe_light(crambin)):
        gpu = read_texture(shadow_pass.trace(gbuffer, light, soft))
        cpu = light_visibility(position, normal, atom, light, occluders, soft)
        valid = atom != -1
        assert gpu.min() >= 0.0 and gpu.max() <= 1.0
        penumbra = valid & (cpu > 0.02) & (cpu < 0.98)
        assert penumbra.sum() > 20, (name, light)  # the shell really produces partial values
        close = np.abs(gpu - cpu)[valid] < 2e-3
        assert close.mean() >= 0.995, (name, close.mean())


def test_soft_shadows_reduce_to_hard_when_the_shell_is_thin(
    crambin, crambin_grid, shadow_pass, scene
):
    name, gbuffer, position, normal, atom, occluders = scene
    valid = atom != -1
    hard_gpu = read_texture(shadow_pass.trace(gbuffer, SUN, HARD_SHADOW))
    # inner == outer == 0: exactly the hard shadow
    same = read_texture(shadow_pass.trace(gbuffer, SUN, SoftShadow(0.0, 0.0, 4.0)))
    assert np.array_equal(same, hard_gpu)
    # inner == outer == 0.5 Å (no growth): the hard shadow of spheres 0.5 Å larger (CPU)
    thick = read_texture(shadow_pass.trace(gbuffer, SUN, SoftShadow(0.5, 0.5, 0.0)))
    grown = Occluders(
        occluders.centers,
        occluders.radii + 0.5,
        occluders.culled,
        occluders.culling,
        None if occluders.probe is None else occluders.probe + [0, 0, 0, 0.5],
    )
    cpu = light_visibility(position, normal, atom, SUN, grown, HARD_SHADOW)
    assert set(np.unique(thick[valid])) <= {0.0, 1.0}
    compared = away_from_boundaries(cpu < 0.5, valid)
    assert ((thick < 0.5) == (cpu < 0.5))[compared].mean() >= 0.995
    assert (thick < 0.5)[valid].mean() > (hard_gpu < 0.5)[
        valid
    ].mean()  # larger spheres, more shadow


def test_shell_thicker_than_the_grid_expansion_is_refused(gl, crambin, shadow_pass, crambin_grid):
    gbuffer = GBuffer.allocate(gl, 4, 4)
    with pytest.raises(ValueError, match="exceeds the grid"):
        shadow_pass.trace(gbuffer, SUN, SoftShadow(0.0, DEFAULT_PROBE_RADIUS + 0.1, 0.0))
    gbuffer.release()


def test_culled_and_clipped_occluders_cast_no_shadow(gl):
    """A receiver sphere under a blocker: shadowed; blocker culled by a plane: lit; blocker
    only partly cut away, so that the shadow ray misses what is left: lit."""
    centers = np.array([[0.0, 0.0, 0.0], [0.0, 5.0, 0.0]])
    grid = sphere_grid(gl, centers, [1.5, 1.5])
    point = np.array([[[0.0, 1.5, 0.0]]])  # top of the receiver, facing the blocker
    up = np.array([[[0.0, 1.0, 0.0]]])
    gbuffer = GBuffer.upload(gl, point, up, np.array([[0]]))
    shadows = ShadowTracer(grid)
    sun = DirectionalLight((0.0, 1.0, 0.0))
    assert read_texture(shadows.trace(gbuffer, sun))[0, 0] == 0.0
    grid.set_culling(Culling(clip_planes=[[0.0, -1.0, 0.0, 3.0]]))  # keeps y <= 3: blocker gone
    assert grid.culled_mask.tolist() == [False, True]
    assert read_texture(shadows.trace(gbuffer, sun))[0, 0] == 1.0
    grid.set_culling(
        Culling(clip_planes=[[-1.0, 0.0, 0.0, -0.5]])
    )  # keeps x <= -0.5: ray at x = 0 passes
    assert grid.culled_mask.tolist() == [False, False]
    assert read_texture(shadows.trace(gbuffer, sun))[0, 0] == 1.0
    grid.set_culling(Culling(clip_planes=[[-1.0, 0.0, 0.0, 0.5]]))  # keeps x <= 0.5: ray blocked
    assert read_texture(shadows.trace(gbuffer, sun))[0, 0] == 0.0
    for thing in (shadows, gbuffer, grid):
        thing.release()


# ------------------------------------------------------------------ the probe light's light buffer
@pytest.fixture(scope="module")
def walking_pass(crambin_grid):
    p = ShadowTracer(crambin_grid, light_buffer=False)
    yield p
    p.release()


def test_light_buffer_equals_the_grid_walk_to_the_bit(crambin, shadow_pass, walking_pass, scene):
    """The light buffer tests only the atoms listed for a ray's direction: the same
    occluders as the walk, so the same minimum, hard and soft, clipped or not."""
    name, gbuffer, position, normal, atom, _ = scene
    lamp = probe_light(crambin)
    moved = PointLight(tuple(np.asarray(lamp.position) + [1.5, -2.0, 1.0]), 20.0)
    for light in (lamp, moved):
        for soft in (HARD_SHADOW, SoftShadow(inner=-0.4, outer=1.0, growth=4.0)):
            listed = read_texture(shadow_pass.trace(gbuffer, light, soft))
            walked = read_texture(walking_pass.trace(gbuffer, light, soft))
            assert np.array_equal(listed, walked), (name, light, soft)
            assert 0.05 < (walked[atom != -1] < 0.5).mean() < 0.95  # shadows to compare
    counts = shadow_pass.light_buffer.counts()
    assert (
        shadow_pass.light_buffer.atoms_in_reach > 100
        and 1 < counts.max() <= shadow_pass.light_buffer.atoms_in_reach
    )


def test_a_point_lights_rays_are_clipped_by_the_cuts_it_lies_beyond(crambin, crambin_grid, scene):
    """Clipped only by the cuts the light is not inside, a ray from a kept point to the
    light is clipped as by all of them: the same visibility wherever the ray origin is kept,
    in and beyond the cube, hard and soft, through the light buffer and the walk. (On a cap
    the origin lies a ray epsilon beyond its cut: there the two may differ by where the ray
    starts, within that epsilon.)"""
    name, gbuffer, position, normal, atom, _ = scene
    culling = crambin_grid.culling
    surface = atom >= 0
    origin = position + normal * ray_epsilon(position)[..., None]
    planes = culling.clip_planes
    kept = surface & np.all(origin @ planes[:, :3].T + planes[:, 3] >= 0, axis=-1)
    if culling.nav_cube is not None:
        centre, half = culling.nav_cube
        kept &= np.all(np.abs(origin - centre) <= half, axis=-1)
    lamp = probe_light(crambin)
    middle = crambin.positions.mean(axis=0)
    lights = [
        lamp,
        PointLight(tuple(middle + [11.0, -1.0, 0.5]), 20.0),
    ]  # the second beyond the cube's +x face
    if name == "cube":
        assert culling.cuts_before(lights[1].position).clip_planes.shape[0] == 1
    shadows = ShadowTracer(crambin_grid)
    walking = ShadowTracer(crambin_grid, light_buffer=False)
    try:
        for light in lights:
            for soft in (HARD_SHADOW, SoftShadow(inner=-0.4, outer=1.0, growth=4.0)):
                for passes in (shadows, walking):
                    cut = read_texture(passes.trace(gbuffer, light, soft))
                    every = read_texture(passes.trace(gbuffer, light, soft, all_cuts=True))
                    assert np.array_equal(cut[kept], every[kept]), (name, light, soft)
                    assert (cut != every)[
                        surface
                    ].mean() <= 0.005  # origins a ray epsilon outside a cut
                    assert (
                        10 < (every[kept] < 0.5).sum() < kept.sum() - 10
                    )  # shadows and light to compare
        assert kept.sum() > 0.3 * surface.sum() and (name == "none" or kept.sum() < surface.sum())
    finally:
        shadows.release()
        walking.release()


def test_light_buffer_lists_what_a_brute_force_cone_test_lists(crambin, crambin_grid, monkeypatch):
    """Each cell lists, nearest first, exactly the atoms in reach whose cone of directions
    (about the lists' centre, radius grown by the slack) meets the cell's: found here
    by sampling each cell's directions densely, as independent of the build's
    closed-form test as it can be. Sampled directions cannot reach a cone's very edge, so
    the build may list more (by its margins), never fewer. Built for three lights in turn:
    the second near enough to the first for the grid's candidates to be kept, the third not."""
    gathered = []
    grid = crambin_grid.grid
    monkeypatch.setattr(
        grid,
        "candidates_in_box",
        lambda lo, hi, gather=grid.candidates_in_box: gathered.append(1) or gather(lo, hi),
    )
    shadows = ShadowTracer(crambin_grid)
    lists = shadows.light_buffer
    lamp = probe_light(crambin)
    try:
        for offset, gathers in (((0.0, 0.0, 0.0), 1), ((1.2, -0.8, 0.5), 1), ((7.0, 5.0, -4.0), 2)):
            light = PointLight(tuple(np.asarray(lamp.position) + offset), lamp.radius)
            lists.build(light.position, light.radius, 0.0)
            assert len(gathered) == gathers and np.allclose(
                lists.centre, light.position, atol=lists.slack
            )
            assert_lists_complete(lists, crambin_grid, lists.centre, cells=8)
    finally:
        shadows.release()


def assert_lists_complete(lists, gpu_grid, centre, cells: int) -> None:
    centres, vdw = gpu_grid.grid.centers, gpu_grid.vdw_radii
    grown = vdw + lists.slack + 1e-3
    table = np.frombuffer(lists.list_atoms.read(), dtype=np.int32)
    listed = np.split(table[lists.n_cells + 1 :][: lists.starts[-1]], lists.starts[1:-1])
    offsets = centres - np.asarray(centre)
    distance = np.linalg.norm(offsets, axis=1)
    rng = np.random.default_rng(int(abs(centre[0]) * 1000))
    n = lists.face_cells
    missed = 0
    for cell in rng.choice(lists.n_cells, cells, replace=False):
        face, j, i = cell // (n * n), (cell // n) % n, cell % n
        axis, sign = face // 2, -1.0 if face % 2 else 1.0
        s, t = np.meshgrid(-1 + (i + rng.random(400)) * 2 / n, -1 + (j + rng.random(400)) * 2 / n)
        directions = np.zeros((s.size, 3))
        directions[:, axis] = sign
        directions[:, (axis + 1) % 3], directions[:, (axis + 2) % 3] = s.ravel(), t.ravel()
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        # an atom is seen through the cell if some sampled ray from the light passes within its
        # grown radius
        along = offsets @ directions.T
        miss = distance[:, None] ** 2 - np.maximum(along, 0.0) ** 2
        seen = np.flatnonzero(
            (miss <= grown[:, None] ** 2).any(axis=1)
            & (distance - grown <= lists.reach)
            & ~gpu_grid.culled_mask
        )
        mine = listed[cell]
        missed += np.setdiff1d(seen, mine).size
        near = distance[mine] - grown[mine]
        assert np.all(np.diff(near) >= -1e-6), cell  # nearest first
    assert missed == 0


def test_light_buffer_of_a_light_with_no_atom_in_reach(crambin, crambin_grid, walking_pass, scene):
    """A light far from every atom lists nothing and its lists still bind and trace: every
    pixel it reaches is lit, as the walk finds."""
    name, gbuffer, *_ = scene
    shadows = ShadowTracer(crambin_grid)
    try:
        far = PointLight(tuple(crambin.positions.max(axis=0) + 40.0), 20.0)
        listed = read_texture(shadows.trace(gbuffer, far, HARD_SHADOW))
        assert shadows.light_buffer.atoms_in_reach == 0 and shadows.light_buffer.counts().sum() == 0
        assert np.array_equal(listed, read_texture(walking_pass.trace(gbuffer, far, HARD_SHADOW)))
    finally:
        shadows.release()


def test_light_buffer_holds_while_the_light_stays_within_its_slack(
    crambin, crambin_grid, walking_pass, scene
):
    """Lists built for one point serve every light within their slack of it (the probe
    sliding along the surface): the same shadows as the walk, bit for bit, hard and soft,
    without being built again; a light beyond the slack builds them anew."""
    name, gbuffer, *_ = scene
    listing = ShadowTracer(crambin_grid)
    lists = listing.light_buffer
    try:
        lamp = probe_light(crambin)
        centre = np.asarray(lamp.position, dtype=np.float64)
        listing.trace(gbuffer, lamp, HARD_SHADOW)
        assert lists.builds == 1 and lists.slack > 0
        rng = np.random.default_rng(3)
        offsets = rng.normal(size=(4, 3))
        offsets *= (
            lists.slack * np.array([1.0, 0.999, 0.6, 0.3]) / np.linalg.norm(offsets, axis=1)
        )[:, None]
        shadowed = []
        for offset in offsets:
            light = PointLight(tuple(centre + offset), lamp.radius)
            listed = read_texture(listing.trace(gbuffer, light, HARD_SHADOW))
            walked = read_texture(walking_pass.trace(gbuffer, light, HARD_SHADOW))
            assert np.array_equal(listed, walked), (name, offset)
            shadowed.append(float((walked < 0.5).mean()))
        assert (
            lists.builds == 1 and len(set(shadowed)) > 1
        )  # kept, and the shadows moved with the light
        soft = SoftShadow(inner=-0.4, outer=1.0, growth=4.0)
        light = PointLight(tuple(centre + offsets[1]), lamp.radius)
        assert np.array_equal(
            read_texture(listing.trace(gbuffer, light, soft)),
            read_texture(walking_pass.trace(gbuffer, light, soft)),
        )
        assert lists.builds == 2  # a new shell: built again
        beyond = PointLight(tuple(centre + offsets[1] + offsets[0] * 2.5), lamp.radius)
        listing.trace(gbuffer, beyond, soft)
        assert lists.builds == 3
    finally:
        listing.release()


def test_sun_buffer_equals_the_grid_walk_to_the_bit(
    crambin, crambin_grid, shadow_pass, walking_pass, scene
):
    """The directional light's buffer tests only the atoms listed across the light at a
    ray's point: the same occluders as the walk (the probe too), so the same minimum, hard
    and soft, clipped or not, from several directions (one along an axis)."""
    name, gbuffer, position, normal, atom, _ = scene
    shadowed = []
    for direction in ((0.45, 0.8, 0.4), (-0.3, 0.2, 0.93), (0.0, 0.0, 1.0), (-0.7, -0.1, -0.7)):
        sun = DirectionalLight(direction)
        # growth 0: the shell is full width at the receiver, so atoms just behind it darken it too
        for soft in (
            HARD_SHADOW,
            SoftShadow(inner=-0.4, outer=1.0, growth=4.0),
            SoftShadow(-0.4, 1.0, 0.0),
        ):
            listed = read_texture(shadow_pass.trace(gbuffer, sun, soft))
            walked = read_texture(walking_pass.trace(gbuffer, sun, soft))
            assert np.array_equal(listed, walked), (name, direction, soft)
        shadowed.append((walked[atom != -1] < 0.5).mean())
    assert sum(0.05 < f < 0.95 for f in shadowed) >= 3, (
        shadowed
    )  # shadows to compare (the last light is behind)
    kept = int((~crambin_grid.culled_mask).sum())
    assert shadow_pass.sun_buffer.entries >= kept  # every kept atom is listed, in a cell at least


def test_sun_buffer_on_a_larger_structure(gl, reference_by_id):
    """1TII with its waters, framed whole and through a navigation cube: the buffer's
    shadows are the walk's, bit for bit."""
    from sasprobe.molecule import load_structure
    from sasprobe.render.lighting.uploaded_grid import UploadedGrid

    structure = load_structure(reference_by_id["1tii"].path, keep_water=True)
    grid = UploadedGrid.from_structure(gl, structure, DEFAULT_PROBE_RADIUS)
    listing, walking = ShadowTracer(grid), ShadowTracer(grid, light_buffer=False)
    try:
        centre = structure.positions.mean(axis=0)
        for culling in (Culling(), Culling(nav_cube=(centre + [3.0, -2.0, 1.0], 9.0))):
            grid.set_culling(culling)
            view, proj = camera(structure)
            gbuffer, _, _, atom = gbuffer_arrays(grid, view, proj)
            try:
                sun = DirectionalLight((0.45, 0.8, 0.4))
                listed = read_texture(listing.trace(gbuffer, sun, HARD_SHADOW))
                walked = read_texture(walking.trace(gbuffer, sun, HARD_SHADOW))
                assert np.array_equal(listed, walked)
                assert 0.05 < (walked[atom >= 0] < 0.5).mean() < 0.95
            finally:
                gbuffer.release()
    finally:
        listing.release()
        walking.release()
        grid.release()


def test_light_buffer_cells_lie_within_their_cones():
    """Every direction falls in the cell the documented cube layout gives it (face 2 axis +
    negative, i and j along the next two axes), within that cell's cone."""
    n = 8
    cones = cell_cones(n)
    rng = np.random.default_rng(11)
    v = rng.normal(size=(20000, 3))
    v = np.concatenate(
        [v, np.eye(3), -np.eye(3), [[1, 1, 1], [1, -1, 0.5]]]
    )  # face edges and corners too
    axis = np.argmax(np.abs(v), axis=1)
    rows = np.arange(v.shape[0])
    major = v[rows, axis]
    s = v[rows, (axis + 1) % 3] / np.abs(major)
    t = v[rows, (axis + 2) % 3] / np.abs(major)
    i = np.clip(np.floor((s * 0.5 + 0.5) * n), 0, n - 1).astype(int)
    j = np.clip(np.floor((t * 0.5 + 0.5) * n), 0, n - 1).astype(int)
    cell = ((2 * axis + (major < 0)) * n + j) * n + i
    unit = v / np.linalg.norm(v, axis=1, keepdims=True)
    angle = np.arccos(np.clip(np.sum(unit * cones[cell, :3], axis=1), -1.0, 1.0))
    assert np.all(angle <= cones[cell, 3] + 1e-9)
    assert np.allclose(np.linalg.norm(cones[:, :3], axis=1), 1.0) and cones[
        :, 3
    ].max() < np.radians(12)
    assert len(np.unique(cell)) == 6 * n * n  # every cell is reached
