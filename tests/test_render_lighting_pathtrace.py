"""Path tracing: the direct-light part equals Lambert × the CPU shadow rays, and the
escape part converges to the CPU Monte-Carlo accessibility (closest-hit bounces)."""

from __future__ import annotations

import numpy as np
import pytest
from sasprobe.molecule import DEFAULT_PROBE_RADIUS
from sasprobe.render.gl.textures import read_texture
from sasprobe.render.lighting.culling import Culling
from sasprobe.render.lighting.materials import atom_materials
from sasprobe.render.lighting.path_tracer import PathTracer
from sasprobe.render.lighting.settings import (
    HARD_SHADOW,
    DirectionalLight,
    PathTracing,
    PointLight,
    probe_falloff,
)

from tests.references.lighting import Occluders, light_visibility, monte_carlo_ao
from tests.support.lighting import (
    away_from_boundaries,
    camera,
    cullings,
    gbuffer_arrays,
    probe_on_surface,
)

pytestmark = pytest.mark.needs_gl(430)  # compute shaders, storage buffers


@pytest.fixture(scope="module")
def scene(crambin, crambin_grid):
    crambin_grid.set_culling(cullings(crambin)["plane"])
    probe = probe_on_surface(crambin)
    crambin_grid.set_probe(probe, DEFAULT_PROBE_RADIUS)
    view, proj = camera(crambin)
    gbuffer, position, normal, atom = gbuffer_arrays(crambin_grid, view, proj)
    yield (
        gbuffer,
        position,
        normal,
        atom,
        Occluders.of(crambin_grid),
        np.linalg.inv(view)[:3, 3],
        probe,
    )
    gbuffer.release()
    crambin_grid.set_culling(Culling())
    crambin_grid.set_probe(None)


def matte(crambin, albedo=None):
    materials = atom_materials(crambin.elements, crambin.colors)
    materials[:, 3] = 0.0  # no highlight: Lambert only
    if albedo is not None:
        materials[:, :3] = albedo
    return materials


def test_direct_light_is_lambert_times_cpu_shadow_rays(crambin, crambin_grid, scene):
    gbuffer, position, normal, atom, occluders, eye, probe = scene
    sun = DirectionalLight((0.45, 0.8, 0.4), intensity=2.0)
    lamp = PointLight(tuple(probe), 14.0, intensity=30.0)
    materials = matte(crambin)
    tracer = PathTracer(crambin_grid, materials)
    radiance = read_texture(
        tracer.accumulate(gbuffer, eye, sun, lamp, PathTracing(bounces=0, spp=1))
    )[..., :3]
    tracer.release()
    on_atom = atom >= 0
    albedo = materials[np.maximum(atom, 0), :3]
    cos_sun = np.clip(normal @ sun.unit(), 0.0, None)
    to_lamp = np.asarray(lamp.position) - position
    dist = np.linalg.norm(to_lamp, axis=-1)
    cos_lamp = np.clip(np.einsum("hwk,hwk->hw", normal, to_lamp) / dist, 0.0, None)
    falloff = probe_falloff(dist, lamp)
    vis_sun = light_visibility(position, normal, atom, sun, occluders, HARD_SHADOW)
    vis_lamp = light_visibility(position, normal, atom, lamp, occluders, HARD_SHADOW)
    expect = (
        albedo
        / np.pi
        * (sun.intensity * cos_sun * vis_sun + lamp.intensity * falloff * cos_lamp * vis_lamp)[
            ..., None
        ]
    )
    classes = (vis_sun > 0.5).astype(int) * 2 + (vis_lamp > 0.5)
    compared = away_from_boundaries(classes, on_atom)
    assert compared.sum() > 0.6 * on_atom.sum()
    close = np.all(np.abs(radiance - expect) <= 1e-4 + 1e-4 * expect, axis=-1)
    assert close[compared].mean() >= 0.995
    assert expect[compared].max() > 0.3 and (vis_lamp[on_atom] < 0.5).any()


def test_escaping_paths_converge_to_monte_carlo_accessibility(crambin, crambin_grid, scene):
    """White matte atoms, no lights, a white sky, one bounce: a pixel's radiance is the
    fraction of its cosine-weighted rays that escape, i.e. AO with unlimited distance."""
    gbuffer, position, normal, atom, occluders, eye, _ = scene
    tracer = PathTracer(crambin_grid, matte(crambin, albedo=1.0))
    settings = PathTracing(bounces=1, spp=64, sky=(1.0, 1.0, 1.0))
    for _ in range(2):
        image = tracer.accumulate(gbuffer, eye, None, None, settings)
    radiance = read_texture(image)[..., 0]
    tracer.release()
    rng = np.random.default_rng(99)
    pick = rng.choice(np.flatnonzero(atom.reshape(-1) >= 0), 500, replace=False)
    cpu = monte_carlo_ao(
        position.reshape(-1, 3)[pick],
        normal.reshape(-1, 3)[pick],
        atom.reshape(-1)[pick],
        occluders,
        1e4,
        16,
        rng,
    )
    err = radiance.reshape(-1)[pick] - cpu
    assert cpu.std() > 0.1
    assert np.sqrt(np.mean(err**2)) <= 0.03
    assert abs(err.mean()) < 0.01


def test_more_bounces_add_light(crambin, crambin_grid, scene):
    gbuffer, _, _, atom, _, eye, _ = scene
    tracer = PathTracer(crambin_grid, matte(crambin, albedo=0.8))
    sun = DirectionalLight((0.45, 0.8, 0.4), intensity=2.0)
    means = []
    for bounces in range(4):
        tracer.reset()
        image = read_texture(
            tracer.accumulate(gbuffer, eye, sun, None, PathTracing(bounces=bounces, spp=8))
        )
        means.append(float(image[atom >= 0, 0].mean()))
    tracer.release()
    assert means[0] < means[1] < means[2] < means[3]  # sky and inter-reflections add up
    assert means[3] - means[2] < means[1] - means[0]  # ... less with every bounce
    with pytest.raises(ValueError):
        PathTracing(bounces=4)
