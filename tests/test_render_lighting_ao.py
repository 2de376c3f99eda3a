"""Ambient occlusion on the GPU against CPU references: the analytic formula on the same
neighbour lists, and ray-traced AO against a cosine-weighted Monte-Carlo estimate."""

from __future__ import annotations

import numpy as np
import pytest
from sasprobe.molecule import DEFAULT_PROBE_RADIUS
from sasprobe.render.camera import fit_bounding_sphere
from sasprobe.render.gl.textures import read_texture
from sasprobe.render.lighting.ao import AmbientOcclusion
from sasprobe.render.lighting.ao.analytic import AnalyticAO
from sasprobe.render.lighting.ao.raytraced import RayTracedAO
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.settings import AO_MODES, AOSettings

from tests.references.lighting import Occluders, analytic_ao, monte_carlo_ao
from tests.support.lighting import camera, cullings, gbuffer_arrays, probe_on_surface, sphere_grid

pytestmark = pytest.mark.needs_gl(430)  # compute shaders, storage buffers

AO_DISTANCE = 8.0


@pytest.fixture(scope="module", params=["none", "plane", "cube"])
def scene(request, crambin, crambin_grid):
    crambin_grid.set_culling(cullings(crambin)[request.param])
    crambin_grid.set_probe(probe_on_surface(crambin), DEFAULT_PROBE_RADIUS)
    view, proj = camera(crambin)
    gbuffer, position, normal, atom = gbuffer_arrays(crambin_grid, view, proj)
    yield request.param, gbuffer, position, normal, atom, Occluders.of(crambin_grid), view, proj
    gbuffer.release()
    crambin_grid.set_culling(Culling())
    crambin_grid.set_probe(None)


@pytest.fixture(scope="module")
def analytic(crambin_grid):
    p = AnalyticAO(crambin_grid)
    yield p
    p.release()


@pytest.mark.parametrize("k", [8, 16, 32])
def test_analytic_ao_equals_the_cpu_formula(analytic, scene, k):
    name, gbuffer, position, normal, atom, occluders, *_ = scene
    analytic.update_probe()
    gpu = read_texture(analytic.compute(gbuffer, k))
    cpu = analytic_ao(
        position, normal, atom, occluders, analytic.neighbours, k, analytic.probe_neighbours
    )
    valid = atom != -1
    assert (atom == -2).sum() > 5  # probe pixels are covered too
    assert np.abs(gpu - cpu).max() <= 1e-4, name
    assert cpu[valid].std() > 0.05 and cpu[valid].min() < 0.5  # real occlusion to compare
    assert np.all(gpu[~valid] == 1.0)


def test_analytic_neighbour_lists_are_the_grid_nearest_neighbours(crambin, analytic):
    diff = crambin.positions[:, None, :] - crambin.positions[None, :, :]
    dist = np.linalg.norm(diff, axis=-1)
    np.fill_diagonal(dist, np.inf)
    brute = np.sort(dist, axis=1)[:, :32]
    got = np.take_along_axis(dist, analytic.neighbours, axis=1)
    assert np.allclose(got, brute)


def test_more_neighbours_never_lighten(analytic, scene):
    _, gbuffer, *_ = scene
    ao8, ao16, ao32 = (read_texture(analytic.compute(gbuffer, k)).copy() for k in (8, 16, 32))
    assert np.all(ao16 <= ao8 + 1e-6) and np.all(ao32 <= ao16 + 1e-6)
    assert (ao8 - ao32).max() > 0.05


def test_ray_traced_ao_converges_to_monte_carlo_reference(crambin, crambin_grid):
    """One run, without culling (llvmpipe is slow; culled traversal is covered by the
    shadow and path-tracing tests), with the probe beside the molecule."""
    crambin_grid.set_probe(probe_on_surface(crambin), DEFAULT_PROBE_RADIUS)
    view, proj = camera(crambin)
    gbuffer, position, normal, atom = gbuffer_arrays(crambin_grid, view, proj)
    occluders = Occluders.of(crambin_grid)
    crambin_grid.set_probe(None)
    rt = RayTracedAO(crambin_grid)
    gpu = read_texture(rt.accumulate(gbuffer, 256, AO_DISTANCE))
    rt.release()
    gbuffer.release()
    # CPU reference on a random sample of 700 pixels, 32 x 32 jittered-stratified rays each
    rng = np.random.default_rng(2024)
    pick = rng.choice(np.flatnonzero(atom.reshape(-1) != -1), 700, replace=False)
    cpu = monte_carlo_ao(
        position.reshape(-1, 3)[pick],
        normal.reshape(-1, 3)[pick],
        atom.reshape(-1)[pick],
        occluders,
        AO_DISTANCE,
        32,
        rng,
        grid=crambin_grid.grid,
    )
    err = gpu.reshape(-1)[pick] - cpu
    assert cpu.std() > 0.1  # AO varies: the comparison has something to see
    assert np.sqrt(np.mean(err**2)) <= 0.02
    assert abs(err.mean()) < 0.005  # no bias


def test_accumulation_over_frames_equals_one_long_frame(crambin_grid, scene):
    _, gbuffer, *_ = scene
    one = RayTracedAO(crambin_grid)
    whole = read_texture(one.accumulate(gbuffer, 32, AO_DISTANCE)).copy()
    frames = RayTracedAO(crambin_grid)
    for _ in range(4):
        frames.accumulate(gbuffer, 8, AO_DISTANCE)
    assert frames.samples == 32
    assert np.abs(read_texture(frames.accumulated) - whole).max() < 1e-5
    frames.reset()
    single = read_texture(frames.accumulate(gbuffer, 1, AO_DISTANCE))
    assert set(np.unique(single)) <= {0.0, 1.0}  # 1 spp: each pixel is one ray, restarted
    one.release()
    frames.release()


def test_every_mode_gives_accessibility_in_range(crambin_grid, scene):
    _, gbuffer, position, normal, atom, _, view, proj = scene
    ao = AmbientOcclusion(crambin_grid)
    valid = atom != -1
    results = {}
    for mode in AO_MODES:
        for sampling in ("point", "line"):
            for half in (False, True):
                if mode != "ssao" and (sampling, half) != ("point", False):
                    continue
                ao.configure(
                    AOSettings(
                        mode=mode,
                        ssao_sampling=sampling,
                        ssao_half_resolution=half,
                        reference_spp=64,
                        reference_total=128,
                    )
                )
                ao.view_changed()
                tex = ao.compute(gbuffer, view, proj)
                while not ao.converged:
                    tex = ao.compute(gbuffer, view, proj)
                image = read_texture(tex).copy()
                assert image.shape == atom.shape
                assert image.min() >= 0.0 and image.max() <= 1.0, (mode, sampling, half)
                assert np.all(image[~valid] == 1.0)
                results[(mode, sampling, half)] = image
                if mode == "reference":
                    reference_samples = ao.samples  # converged: every sample it was asked for
    assert np.all(results[("off", "point", False)] == 1.0)
    for key, image in results.items():
        if key[0] != "off":
            assert image[valid].mean() < 0.97, key  # everything but 'off' finds occlusion
    # hybrid is analytic x ray-traced (1 spp, blurred): at most either factor's occlusion
    hybrid, analytic = results[("hybrid", "point", False)], results[("analytic", "point", False)]
    assert np.all(hybrid <= analytic + 1e-6)
    assert reference_samples == 128
    ao.release()


def test_ssao_leaves_convex_surfaces_unoccluded_and_darkens_a_crevice(gl):
    """One big sphere: nothing occludes it where it faces the camera (towards its outline the
    depth buffer hides its curvature and line sampling darkens it: a known limit of the
    height-field assumption, shown in the benchmark). Two touching spheres: the contact
    darkens."""
    for centers, radii, crevice in (
        ([[0.0, 0.0, 0.0]], [6.0], False),
        ([[-3.0, 0.0, 0.0], [3.0, 0.0, 0.0]], [3.2, 3.2], True),
    ):
        grid = sphere_grid(gl, centers, radii)
        view, proj = fit_bounding_sphere(
            np.array(centers), np.array(radii), 4 / 3, (0.0, 0.0, 1.0), fill=0.8
        )
        gbuffer, position, normal, atom = gbuffer_arrays(grid, view, proj, 96, 72)
        ao = AmbientOcclusion(grid)
        valid = atom != -1
        near_contact = valid & (np.abs(position[..., 0]) < 1.0)
        face_on = valid & (normal[..., 2] > 0.7)
        for sampling in ("point", "line"):
            ao.configure(
                AOSettings(mode="ssao", ssao_sampling=sampling, ssao_radius=2.0, ssao_samples=24)
            )
            image = read_texture(ao.compute(gbuffer, view, proj))
            if crevice:
                assert image[near_contact].mean() < image[valid & ~near_contact].mean() - 0.05, (
                    sampling
                )
            else:
                assert image[face_on].min() > 0.97, sampling
        ao.release()
        gbuffer.release()
        grid.release()
