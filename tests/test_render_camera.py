"""Camera maths (no GL): matrices, auto-fit, --camera specs, arcball, zoom and pan."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sasprobe.render.camera import Camera, camera_from_spec, parse_camera, rotation_matrix


def project(cam: Camera, aspect: float, points: np.ndarray) -> np.ndarray:
    clip = np.c_[points, np.ones(len(points))] @ (cam.projection(aspect) @ cam.view()).T
    return clip[:, :3] / clip[:, 3:]


def test_view_matrix_is_a_rigid_look_at():
    cam = Camera(eye=[10.0, 5.0, 30.0], target=[1.0, 2.0, 3.0], up=[0.0, 1.0, 0.0])
    v = cam.view()
    np.testing.assert_allclose(v[:3, :3] @ v[:3, :3].T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(v @ [10.0, 5.0, 30.0, 1.0], [0, 0, 0, 1], atol=1e-12)
    target_view = v @ [1.0, 2.0, 3.0, 1.0]
    np.testing.assert_allclose(target_view[:2], 0.0, atol=1e-12)
    assert target_view[2] < 0  # OpenGL: the camera looks down -z


@pytest.mark.parametrize("aspect", [0.5, 1.0, 16 / 9])
def test_fitted_camera_shows_the_whole_bounding_sphere(aspect):
    center, radius = np.array([3.0, -2.0, 7.0]), 25.0
    cam = Camera.fitted(center, radius, aspect, direction=(0.3, 0.5, 0.8))
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(2000, 3))
    points = center + radius * dirs / np.linalg.norm(dirs, axis=1)[:, None]
    ndc = project(cam, aspect, points)
    assert np.abs(ndc[:, :2]).max() <= 1.0
    assert np.abs(ndc[:, :2]).max() > 0.85  # and fills the view
    assert ndc[:, 2].min() >= -1.0 and ndc[:, 2].max() <= 1.0  # within near/far


def test_parse_camera_specs():
    spec = parse_camera("eye=1,2,3 target=4,5,6;up=0,0,1 fov=30")
    np.testing.assert_array_equal(spec["eye"], [1, 2, 3])
    np.testing.assert_array_equal(spec["up"], [0, 0, 1])
    assert spec["fov"] == 30
    cam = camera_from_spec(parse_camera("fov=25"), np.zeros((1, 3)), np.array([10.0]), 1.0)
    assert cam.fov_y == 25 and np.allclose(cam.target, 0)
    side = camera_from_spec(
        parse_camera("dir=1,0,0 target=1,2,3"), np.zeros((1, 3)), np.array([10.0]), 1.0
    )
    np.testing.assert_allclose(side.target, [1, 2, 3])
    np.testing.assert_allclose((side.eye - side.target) / side.distance, [1, 0, 0], atol=1e-12)
    for bad in [
        "",
        "eye=1,2",
        "eye=a,b,c",
        "zoom=2",
        "fov=0",
        "eye=1,1,1 target=1,1,1",
        "eye=0,0,5 target=0,0,0 up=0,0,1",
        "up=0,0,0",
        "fov=1 fov=2",
        "eye=1,2,nan",
        "dir=0,0,0",
        "eye=1,2,3 dir=0,0,1",
        "dir=0,1,0 up=0,2,0",
    ]:
        with pytest.raises(ValueError):
            parse_camera(bad)


@pytest.mark.parametrize("aspect", [16 / 9, 0.6])
def test_framing_puts_every_sphere_inside_and_spans_the_fill(aspect):
    """Exactly framed: no sphere crosses the narrowed frustum, and the limiting side is
    spanned to `fill` (the sphere silhouettes' extreme tangents, computed independently)."""
    rng = np.random.default_rng(3)
    centers = rng.normal(size=(400, 3)) * [30.0, 12.0, 8.0] + [
        5.0,
        -7.0,
        20.0,
    ]  # an elongated cloud
    radii = rng.uniform(1.2, 2.0, 400)
    cam = Camera.framing(centers, radii, aspect, fov_y=40.0, direction=(0.2, 0.3, 1.0), fill=0.9)
    b = cam.basis()
    local = (centers - cam.eye) @ b  # view coordinates, the camera looking down -z
    depth = -local[:, 2]
    assert depth.min() > radii.max()
    extents = []
    for axis, half in ((0, np.tan(np.radians(20.0)) * aspect), (1, np.tan(np.radians(20.0)))):
        # silhouette of a sphere in the (axis, z) plane: tangent slopes from the eye
        d = np.hypot(local[:, axis], depth)
        angle, spread = np.arctan2(local[:, axis], depth), np.arcsin(radii / d)
        lo, hi = np.tan(angle - spread).min() / half, np.tan(angle + spread).max() / half
        assert lo >= -0.9 - 1e-9 and hi <= 0.9 + 1e-9
        extents.append(hi - lo)
    assert max(extents) == pytest.approx(1.8, abs=0.02)  # the limiting side: 90 % of it


def test_zoom_towards_keeps_the_point_under_the_cursor():
    cam = Camera(eye=[0.0, 0.0, 50.0], target=[0.0, 0.0, 0.0])
    point = np.array([[6.0, -3.0, 2.0]])
    before = project(cam, 1.5, point)[0]
    cam.zoom_towards(point[0], 0.5)
    after = project(cam, 1.5, point)[0]
    np.testing.assert_allclose(after[:2], before[:2], atol=1e-12)
    assert cam.distance == pytest.approx(25.0)
    cam.centre_on([1.0, 1.0, 1.0])
    np.testing.assert_allclose(
        project(cam, 1.5, np.array([[1.0, 1.0, 1.0]]))[0][:2], 0.0, atol=1e-12
    )


def test_arcball_turns_the_molecule_with_the_pointer_and_keeps_distance():
    cam = Camera(eye=[0.0, 0.0, 50.0], target=[0.0, 0.0, 0.0])
    marker = np.array([[0.0, 0.0, 10.0]])  # a point on the near side of the molecule
    before = project(cam, 1.0, marker)[0]
    cam.arcball((0.0, 0.0), (0.3, 0.0))  # drag to the right
    after = project(cam, 1.0, marker)[0]
    assert after[0] > before[0] + 0.05  # the near side follows the pointer
    assert math.isclose(cam.distance, 50.0, rel_tol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(cam.up), 1.0, atol=1e-12)


def test_zoom_and_pan():
    cam = Camera(eye=[0.0, 0.0, 50.0], target=[1.0, 2.0, 0.0])
    cam.zoom(0.5)
    assert math.isclose(cam.distance, np.linalg.norm([-1.0, -2.0, 50.0]) * 0.5, rel_tol=1e-12)
    marker = np.array([[1.0, 2.0, 0.0]])
    before = project(cam, 1.0, marker)[0]
    cam.pan(40.0, 0.0, viewport_height=400)  # pointer 40 px to the right
    after = project(cam, 1.0, marker)[0]
    np.testing.assert_allclose((after[0] - before[0]) * 200, 40.0, rtol=0.05)  # the picture follows


def test_rotation_matrix_is_a_rotation():
    r = rotation_matrix(np.array([1.0, 2.0, 3.0]), 0.7)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert math.isclose(np.linalg.det(r), 1.0)
