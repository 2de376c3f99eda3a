"""Shadows traced on the GPU through the grid against the numpy ray tester on the same
G-buffer positions (directional and probe light; hard and Parker soft; with and without
clipping and cube culling)."""

from __future__ import annotations

import numpy as np
import pytest

from sasprobe.molecule import DEFAULT_PROBE_RADIUS
from sasprobe.render.lighting.grid import Culling
from sasprobe.render.gl.textures import read_texture
from sasprobe.render.lighting.gbuffer import GBuffer
from sasprobe.render.lighting.settings import HARD_SHADOW, DirectionalLight, PointLight, SoftShadow
from tests.lighting_reference import Occluders, light_visibility
from sasprobe.render.lighting.shadows import ShadowPass
from tests.lighting_support import away_from_boundaries, camera, cullings, gbuffer_arrays, probe_on_surface, sphere_grid

pytestmark = pytest.mark.needs_gl(430)  # compute shaders, storage buffers

SUN = DirectionalLight((0.45, 0.8, 0.4))


def probe_light(structure) -> PointLight:
    """The probe's light: the probe resting on the surface facing the camera."""
    return PointLight(tuple(probe_on_surface(structure)), 14.0)


@pytest.fixture(scope="module")
def shadow_pass(crambin_grid):
    p = ShadowPass(crambin_grid)
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
    traced = valid if light_kind == "directional" else valid & (
        np.linalg.norm(position - np.asarray(light.position), axis=-1) <= light.radius)
    assert traced.sum() > 500 and 0.1 < shadowed[traced].mean() < 0.9, (name, shadowed[traced].mean())
    compared = away_from_boundaries(shadowed, valid)
    assert compared.sum() > 0.6 * valid.sum()
    agreement = ((gpu < 0.5) == shadowed)[compared].mean()
    assert agreement >= 0.995, (name, light_kind, agreement)
    assert np.all(gpu[~valid] == 1.0)


def test_probe_light_is_limited_to_its_radius(crambin, shadow_pass, scene):
    _, gbuffer, position, normal, atom, _ = scene
    light = probe_light(crambin)
    gpu = read_texture(shadow_pass.trace(gbuffer, light, HARD_SHADOW))
    far = (atom != -1) & (np.linalg.norm(position - np.asarray(light.position), axis=-1) > light.radius + 1e-3)
    assert far.sum() > 100 and np.all(gpu[far] == 1.0)  # not traced: unlit by attenuation, not shadow


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


def test_soft_shadows_reduce_to_hard_when_the_shell_is_thin(crambin, crambin_grid, shadow_pass, scene):
    name, gbuffer, position, normal, atom, occluders = scene
    valid = atom != -1
    hard_gpu = read_texture(shadow_pass.trace(gbuffer, SUN, HARD_SHADOW))
    # inner == outer == 0: exactly the hard shadow
    same = read_texture(shadow_pass.trace(gbuffer, SUN, SoftShadow(0.0, 0.0, 4.0)))
    assert np.array_equal(same, hard_gpu)
    # inner == outer == 0.5 Å (no growth): the hard shadow of spheres 0.5 Å larger (CPU)
    thick = read_texture(shadow_pass.trace(gbuffer, SUN, SoftShadow(0.5, 0.5, 0.0)))
    grown = Occluders(occluders.centers, occluders.radii + 0.5, occluders.culled, occluders.culling,
                      None if occluders.probe is None else occluders.probe + [0, 0, 0, 0.5])
    cpu = light_visibility(position, normal, atom, SUN, grown, HARD_SHADOW)
    assert set(np.unique(thick[valid])) <= {0.0, 1.0}
    compared = away_from_boundaries(cpu < 0.5, valid)
    assert ((thick < 0.5) == (cpu < 0.5))[compared].mean() >= 0.995
    assert (thick < 0.5)[valid].mean() > (hard_gpu < 0.5)[valid].mean()  # larger spheres, more shadow


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
    shadows = ShadowPass(grid)
    sun = DirectionalLight((0.0, 1.0, 0.0))
    assert read_texture(shadows.trace(gbuffer, sun))[0, 0] == 0.0
    grid.set_culling(Culling(clip_planes=[[0.0, -1.0, 0.0, 3.0]]))  # keeps y <= 3: blocker gone
    assert grid.culled_mask.tolist() == [False, True]
    assert read_texture(shadows.trace(gbuffer, sun))[0, 0] == 1.0
    grid.set_culling(Culling(clip_planes=[[-1.0, 0.0, 0.0, -0.5]]))  # keeps x <= -0.5: ray at x = 0 passes
    assert grid.culled_mask.tolist() == [False, False]
    assert read_texture(shadows.trace(gbuffer, sun))[0, 0] == 1.0
    grid.set_culling(Culling(clip_planes=[[-1.0, 0.0, 0.0, 0.5]]))  # keeps x <= 0.5: ray blocked
    assert read_texture(shadows.trace(gbuffer, sun))[0, 0] == 0.0
    for thing in (shadows, gbuffer, grid):
        thing.release()
