"""Screen rectangles (render/rects.py), what the frame planner's regions are made of, against
brute force: a sphere's rectangle holds every pixel whose ray meets it; the atoms'
rectangle holds every point of every sphere and little more."""

from __future__ import annotations

import numpy as np
from sasprobe.render.camera import Camera
from sasprobe.render.rects import atoms_rect, sphere_rect, union_rect


def test_rectangles_hold_the_sphere():
    view = Camera(eye=(0.0, 0.0, 30.0), target=(0.0, 0.0, 0.0)).view()
    proj = Camera(eye=(0.0, 0.0, 30.0), target=(0.0, 0.0, 0.0)).projection(4 / 3)
    size = (160, 120)
    rect = sphere_rect((2.0, -1.0, 3.0), 1.4, proj @ view, size)
    # every pixel whose ray meets the sphere lies inside (brute force over the frame)
    inv = np.linalg.inv(proj @ view)
    xs, ys = np.meshgrid(np.arange(size[0]) + 0.5, np.arange(size[1]) + 0.5)
    ndc = np.stack(
        [xs / size[0] * 2 - 1, ys / size[1] * 2 - 1, np.ones_like(xs), np.ones_like(xs)], axis=-1
    )
    far = ndc @ inv.T
    d = far[..., :3] / far[..., 3:] - np.array([0.0, 0.0, 30.0])
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    oc = np.array([2.0, -1.0, 3.0]) - np.array([0.0, 0.0, 30.0])
    b = d @ oc
    hit = b * b - (oc @ oc - 1.4**2) >= 0
    x0, y0, w, h = rect
    inside = np.zeros_like(hit)
    inside[y0 : y0 + h, x0 : x0 + w] = True
    assert hit.any() and np.all(inside[hit])
    assert w * h < 0.1 * size[0] * size[1]
    assert sphere_rect((0.0, 0.0, 30.5), 1.0, proj @ view, size) == (
        0,
        0,
        160,
        120,
    )  # holds the eye
    assert sphere_rect((500.0, 0.0, 0.0), 1.0, proj @ view, size) is None  # off screen
    assert union_rect(None, (1, 2, 3, 4)) == (1, 2, 3, 4)
    assert union_rect((0, 0, 2, 2), (5, 5, 1, 1)) == (0, 0, 6, 6)


def test_the_molecules_rectangle_holds_every_atom_and_little_more():
    """atoms_rect (what the probe's reach is clipped to) against brute force: points on every
    sphere projected lie inside, for cameras near and far, on and off the molecule, and the
    rectangle is no more than 6 pixels wider on a side than what they cover (3 at the median)
    where no sphere comes within ten radii of the eye."""
    rng = np.random.default_rng(3)
    size = (160, 120)
    directions = rng.normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    slacks = []
    for trial in range(30):
        centres = rng.normal(size=(40, 3)) * 8.0
        camera = Camera.fitted(
            centres.mean(axis=0) + rng.normal(size=3) * 6.0,
            20.0 * rng.uniform(0.3, 1.5),
            size[0] / size[1],
            direction=rng.normal(size=3),
        )
        viewproj = camera.projection(size[0] / size[1]) @ camera.view()
        rect = atoms_rect(centres, 1.8, viewproj, size)
        points = (centres[:, None, :] + 1.8 * directions[None]).reshape(-1, 3)
        clip = np.column_stack([points, np.ones(len(points))]) @ viewproj.T
        if not (clip[:, 3] > 0).all():  # a sphere reaches behind the eye
            assert rect == (0, 0, *size)
            continue
        pixels = (clip[:, :2] / clip[:, 3:4] * 0.5 + 0.5) * size
        on_screen = pixels[np.all((pixels >= 0) & (pixels < size), axis=1)]
        if rect is None:
            assert on_screen.size == 0
            continue
        x, y, w, h = rect
        assert np.all(on_screen >= (x, y)) and np.all(on_screen <= (x + w, y + h)), trial
        lo = np.clip(np.floor(pixels.min(axis=0)), 0, size)  # every point's box, cut by the frame
        hi = np.clip(np.ceil(pixels.max(axis=0)), 0, size)
        slack = np.concatenate([lo - (x, y), (x + w, y + h) - hi])
        slack = slack[np.concatenate([lo > 0, hi < size])]  # sides the frame does not cut
        if clip[:, 3].min() > 10 * 1.8:  # loose only for spheres close to the eye, beside it
            slacks.extend(slack)
    assert len(slacks) > 20 and max(slacks) <= 6 and np.median(slacks) <= 3, slacks
    eye_plane = Camera(eye=(0.0, 0.0, 30.0), target=(0.0, 0.0, 0.0))
    viewproj = eye_plane.projection(4 / 3) @ eye_plane.view()
    assert atoms_rect(np.array([[0.0, 0.0, 29.5]]), 1.0, viewproj, size) == (
        0,
        0,
        160,
        120,
    )  # reaches the eye
    assert atoms_rect(np.zeros((0, 3)), 1.0, viewproj, size) is None
