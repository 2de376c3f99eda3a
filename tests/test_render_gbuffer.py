"""The G-buffer of the impostor pass against an independent numpy ray caster.

Same view and projection on both sides; atom ids must agree on >= 99.5 % of the pixels
away from silhouettes and sphere-sphere seams, positions within 1e-3 Å and normals
within 1e-3 there.
"""

from __future__ import annotations

import numpy as np
import pytest
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, load_structure
from sasprobe.render.camera import Camera
from sasprobe.render.gbuffer_export import gbuffer_arrays
from sasprobe.render.gl.targets import KIND_BACKBONE, KIND_CAP, KIND_PROBE, KIND_SPHERE
from sasprobe.render.renderer import Renderer
from sasprobe.render.scene_state import NavCube, Probe, SceneState, normalise_plane

from tests.support.render import edge_mask, reference_cast

SIZE = (200, 150)


def render_gbuffer(gl, scene, camera, size=SIZE, mode="quad"):
    renderer = Renderer(gl, scene, size, sphere_mode=mode)
    try:
        renderer.render(camera)
        return gbuffer_arrays(renderer)
    finally:
        renderer.release()


def compare_with_reference(g, centers, radii, ids, planes=(), mask=None, min_agree=0.995):
    """Assert the agreement with the reference caster; returns the reference for further checks."""
    w, h = (int(v) for v in g["viewport"])
    ref_id, ref_pos, ref_nrm, ref_cap = reference_cast(
        g["view"], g["proj"], w, h, centers, radii, ids, planes
    )
    interior = ~edge_mask(ref_id)
    if mask is not None:
        interior &= mask
    assert interior.sum() > 0.1 * w * h, "the view shows too little to compare"
    agree = g["atom_id"][interior] == ref_id[interior]
    assert agree.mean() >= min_agree, (
        f"atom ids agree on only {agree.mean():.4%} of interior pixels"
    )
    both = interior & (g["atom_id"] == ref_id) & (ref_id >= 0)
    pos_err = np.abs(g["position"][both] - ref_pos[both]).max()
    nrm_err = np.abs(g["normal"][both] - ref_nrm[both]).max()
    assert pos_err <= 1e-3, f"position error {pos_err:.2e} Å"
    assert nrm_err <= 1e-3, f"normal error {nrm_err:.2e}"
    return ref_id, ref_pos, ref_nrm, ref_cap


def fitted_camera(scene, size=SIZE, **kw):
    center, radius = scene.bounding_sphere()
    return Camera.fitted(center, radius, size[0] / size[1], **kw)


def test_whole_molecule_matches_reference(gl, crambin):
    scene = SceneState(crambin)
    g = render_gbuffer(gl, scene, fitted_camera(scene))
    s = crambin
    compare_with_reference(g, s.positions, s.vdw_radii, np.arange(s.n_atoms))
    covered = g["atom_id"] >= 0
    assert set(np.unique(g["kind"][covered])) == {KIND_SPHERE}


def test_close_oblique_view_keeps_spheres_at_the_screen_edge(gl, crambin):
    """A wide-angle view from inside the molecule's bounding box, many spheres cut by the
    image border: none may vanish (point sprites would) and perspective must stay exact."""
    s = crambin
    center = s.positions.mean(axis=0)
    camera = Camera(
        eye=center + np.array([14.0, 9.0, 16.0]),
        target=center + np.array([-2.0, 1.0, 0.0]),
        up=np.array([0.2, 1.0, 0.1]),
        fov_y=75.0,
    )
    scene = SceneState(s)
    g = render_gbuffer(gl, scene, camera)
    compare_with_reference(g, s.positions, s.vdw_radii, np.arange(s.n_atoms))
    border = np.concatenate(
        [g["atom_id"][0], g["atom_id"][-1], g["atom_id"][:, 0], g["atom_id"][:, -1]]
    )
    assert np.count_nonzero(border >= 0) > 50, "the view should put spheres across the image border"


def test_larger_structure_matches_reference(gl, reference_by_id):
    s = load_structure(reference_by_id["1oky"].path)
    scene = SceneState(s)
    g = render_gbuffer(gl, scene, fitted_camera(scene, direction=(0.3, 0.5, 0.8)))
    compare_with_reference(g, s.positions, s.vdw_radii, np.arange(s.n_atoms))


def test_camera_inside_a_sphere_sees_its_solid_cap(gl, crambin):
    """Zoomed into an atom, the atom is a solid: the near plane cuts it into a cap that
    fills the view (it must not vanish and show what lies behind it)."""
    s = crambin
    top = int(np.argmax(s.positions[:, 2]))
    eye = s.positions[top] + np.array([0.0, 0.0, 0.5 * s.vdw_radii[top]])
    inside = np.flatnonzero(np.linalg.norm(s.positions - eye, axis=1) < s.vdw_radii)
    assert inside.tolist() == [top], "the eye should be inside exactly one sphere"
    camera = Camera(
        eye=eye, target=s.positions.mean(axis=0), up=np.array([0.0, 1.0, 0.0]), fov_y=60.0
    )
    g = render_gbuffer(gl, SceneState(s), camera)
    forward = -camera.basis()[:, 2]
    near = np.array([*forward, -float(forward @ camera.eye) - camera.near])
    compare_with_reference(g, s.positions, s.vdw_radii, np.arange(s.n_atoms), near[None, :])
    assert (g["atom_id"] == top).all() and (g["kind"] == KIND_CAP).all()
    np.testing.assert_allclose(g["normal"], np.broadcast_to(-forward, g["normal"].shape), atol=1e-3)


def test_clip_planes_cap_atoms_and_cull_those_behind(gl, crambin):
    s = crambin
    center = s.positions.mean(axis=0)
    planes = [
        normalise_plane([0.6, 0.2, 0.77, -float(np.array([0.6, 0.2, 0.77]) @ center) + 1.0]),
        normalise_plane([-0.3, 0.9, -0.1, -float(np.array([-0.3, 0.9, -0.1]) @ center) + 6.0]),
    ]
    scene = SceneState(s, clip_planes=planes)
    camera = fitted_camera(
        scene, direction=(-0.4, -0.6, -0.7)
    )  # on the removed side: facing the cut
    renderer = Renderer(gl, scene, SIZE)
    try:
        renderer.render(camera)
        g = gbuffer_arrays(renderer)
        drawn = set(scene.sphere_selection(camera).tolist())
    finally:
        renderer.release()
    P = np.array(planes)
    dist = s.positions @ P[:, :3].T + P[:, 3]
    wholly_behind = np.any(dist < -s.vdw_radii[:, None], axis=1)
    assert wholly_behind.sum() > 20 and (~wholly_behind).sum() > 20
    assert drawn == set(np.flatnonzero(~wholly_behind).tolist()), (
        "CPU culling must drop exactly the atoms wholly behind a plane"
    )
    np.testing.assert_allclose(g["clip_planes"], P)
    ref_id, *_ = compare_with_reference(g, s.positions, s.vdw_radii, np.arange(s.n_atoms), P)
    shown = set(np.unique(g["atom_id"][g["atom_id"] >= 0]).tolist())
    assert not shown & set(np.flatnonzero(wholly_behind).tolist()), (
        "culled atoms appear in the image"
    )
    # Cap pixels: on one of the planes and carrying that plane's outward normal.
    cap = g["kind"] == KIND_CAP
    assert cap.sum() > 200, "the planes should cut visible caps"
    p, n = g["position"][cap], g["normal"][cap]
    on_plane = np.abs(p @ P[:, :3].T + P[:, 3])  # (pixels, planes)
    which = np.argmin(on_plane, axis=1)
    assert on_plane[np.arange(len(p)), which].max() <= 1e-3
    np.testing.assert_allclose(n, -P[which, :3], atol=1e-3)
    # Every kept point lies on the kept side of every plane.
    covered = g["atom_id"] >= 0
    assert (g["position"][covered] @ P[:, :3].T + P[:, 3]).min() >= -1e-3


def test_navigation_cube_spheres_inside_backbone_outside(gl, reference_by_id):
    s = load_structure(reference_by_id["1oky"].path)
    center = s.positions[s.n_atoms // 2]
    cube = NavCube(center=center.copy(), half=7.0)
    scene = SceneState(s, nav_cube=cube)
    camera = fitted_camera(scene, direction=(0.2, 0.4, 0.9))
    renderer = Renderer(gl, scene, (240, 180))
    try:
        renderer.render(camera)
        g = gbuffer_arrays(renderer)
        drawn = scene.sphere_selection(camera)
    finally:
        renderer.release()
    lo, hi = cube.bounds()
    gap = s.positions - np.clip(s.positions, lo, hi)
    overlapping = np.flatnonzero(np.einsum("ij,ij->i", gap, gap) <= s.vdw_radii**2)
    assert 100 < overlapping.size < 600
    np.testing.assert_array_equal(np.sort(drawn), overlapping)
    np.testing.assert_allclose(g["nav_cube"], [*center, 7.0])
    atoms = (g["kind"] == KIND_SPHERE) | (g["kind"] == KIND_CAP)
    assert set(np.unique(g["atom_id"][atoms]).tolist()) <= set(overlapping.tolist())
    # Spheres are cut to the cube (caps on its faces): compare with the reference where no trace
    # covers.
    compare_with_reference(
        g,
        s.positions[overlapping],
        s.vdw_radii[overlapping],
        overlapping,
        cube.planes(),
        mask=g["kind"] != KIND_BACKBONE,
    )
    inside = np.all(np.abs(g["position"][atoms] - center) <= 7.0 + 1e-3, axis=1)
    assert inside.all(), "sphere pixels outside the cube"
    # The backbone trace is drawn, outside the cube only, on C-alpha to C-alpha segments.
    bb = g["kind"] == KIND_BACKBONE
    assert bb.sum() > 300
    p = g["position"][bb]
    assert np.all(np.any(np.abs(p - center) > 7.0 - 1e-3, axis=1)), "backbone drawn inside the cube"
    starts = np.concatenate([seg[:-1] for seg in s.backbone if len(seg) > 1])
    ends = np.concatenate([seg[1:] for seg in s.backbone if len(seg) > 1])
    a, b = s.positions[starts], s.positions[ends]
    ab = b - a
    t = np.clip(
        np.einsum("pki,ki->pk", p[:, None, :] - a[None], ab) / np.einsum("ki,ki->k", ab, ab), 0, 1
    )
    dist = np.linalg.norm(p[:, None, :] - (a[None] + t[..., None] * ab[None]), axis=2).min(axis=1)
    assert dist.max() < 1e-3, "backbone pixels off the C-alpha trace"
    ids = g["atom_id"][bb]
    assert set(np.unique(ids).tolist()) <= set(np.concatenate([starts, ends]).tolist())


def test_probe_drawn_unclipped_and_touched_atom_kept(gl, crambin):
    s = crambin
    atom = 120
    direction = np.array([0.0, 0.0, 1.0])
    probe_center = s.positions[atom] + direction * (s.vdw_radii[atom] + 1.4)
    scene = SceneState(s, probe=Probe(center=probe_center, touched_atom=atom))
    scene.effects.probe_plane = True
    camera = Camera(eye=probe_center + np.array([2.0, 3.0, 15.0]), target=probe_center, fov_y=35.0)
    g = render_gbuffer(gl, scene, camera)
    probe_px = g["kind"] == KIND_PROBE
    assert probe_px.sum() > 500
    # Never hidden: every pixel of the probe's own disc shows the probe.
    w, h = SIZE
    disc, *_ = reference_cast(
        g["view"], g["proj"], w, h, probe_center[None], np.array([1.4]), np.array([-2])
    )
    inner = (disc == -2) & ~edge_mask(disc)
    assert inner.sum() > 500 and probe_px[inner].all()
    assert np.all(g["atom_id"][probe_px] == -2)
    r = np.linalg.norm(g["position"][probe_px] - probe_center, axis=1)
    np.testing.assert_allclose(r, 1.4, atol=1e-3)
    # The probe plane (square to the view axis, at most a probe radius behind the probe
    # centre) is exported and nothing in front of it hides the probe's front half.
    assert g["clip_planes"].shape == (1, 4)
    pl = g["clip_planes"][0]
    np.testing.assert_allclose(
        pl[:3], (camera.target - camera.eye) / np.linalg.norm(camera.target - camera.eye)
    )
    assert -1.4 - 1e-9 <= pl[:3] @ probe_center + pl[3] <= 1e-9
    covered = g["atom_id"] >= 0
    assert (g["position"][covered] @ pl[:3] + pl[3]).min() >= -1e-3


def test_the_probe_plane_stands_still_within_a_step(crambin):
    """While the probe moves within one depth step (a probe radius; and anywhere across the
    view) the plane is the same to the bit, so the layer it cuts can be kept; past the step
    it moves on by one step."""
    center = crambin.positions.mean(axis=0)
    step = DEFAULT_PROBE_RADIUS
    center[2] = (np.floor(center[2] / step) + 0.5) * step  # the view looks down -z: mid-step
    camera = Camera(eye=center + np.array([0.0, 0.0, 40.0]), target=center)
    scene = SceneState(crambin, probe=Probe(center=center.copy()))
    scene.effects.probe_plane = True
    first = scene.probe_plane(camera)
    np.testing.assert_allclose(first[:3], [0.0, 0.0, -1.0])
    for offset in ([3.0, -2.0, 0.4 * step], [-5.0, 4.0, -0.4 * step], [0.5, 0.5, 0.1 * step]):
        scene.probe = Probe(center=center + offset)
        assert scene.probe_plane(camera).tobytes() == first.tobytes(), offset
    scene.probe = Probe(
        center=center + [0.0, 0.0, -0.6 * step]
    )  # into the next step, away from the eye
    assert scene.probe_plane(camera)[3] == pytest.approx(first[3] - step, abs=1e-12)


@pytest.mark.parametrize("mode,min_agree", [("sprite", 0.995), ("mesh", 0.97)])
def test_other_sphere_modes_match_reference(gl, crambin, mode, min_agree):
    """Point sprites cast the same rays (exact where the whole molecule is in view);
    the 648-triangle mesh baseline approximates the spheres (looser agreement, and its
    positions are only checked to the mesh's faceting error)."""
    s = crambin
    scene = SceneState(s)
    g = render_gbuffer(gl, scene, fitted_camera(scene), mode=mode)
    if mode == "sprite":
        compare_with_reference(g, s.positions, s.vdw_radii, np.arange(s.n_atoms))
        return
    w, h = SIZE
    ref_id, ref_pos, _, _ = reference_cast(
        g["view"], g["proj"], w, h, s.positions, s.vdw_radii, np.arange(s.n_atoms)
    )
    interior = ~edge_mask(ref_id)
    assert (g["atom_id"][interior] == ref_id[interior]).mean() >= min_agree
    both = interior & (g["atom_id"] == ref_id) & (ref_id >= 0)
    assert (
        np.abs(g["position"][both] - ref_pos[both]).max() < 0.1
    )  # chord error of 20-degree facets on r <= 1.8 Å
