"""The probe cues pass and the readout's touched residue: the probe's outline only where it
is hidden, the ghost tip with its spring, the force arrow's colour against the ratings,
the arrow at the edge for a probe off screen. Pixels are compared with the same frame
drawn without the cues (the pass removed), so what changed is what the cues drew."""

from __future__ import annotations

import numpy as np
from sasprobe.molecule.colors import FORCE_COLORS
from sasprobe.molecule.residues import touched_label
from sasprobe.render.camera import Camera
from sasprobe.render.passes.probe_cues import GHOST_COLOR, OUTLINE_COLOR
from sasprobe.render.renderer import Renderer
from sasprobe.render.scene_state import Effects, Probe, SceneState

SIZE = (200, 150)


def frames(gl, scene, camera):
    """(image with the cues, image without them, G-buffer kind) of one frame, fxaa off."""
    out = []
    for cues in (True, False):
        renderer = Renderer(gl, scene, SIZE)
        if not cues:
            renderer.passes.remove(renderer.pass_named("probe_cues"))
        try:
            renderer.render(camera)
            t = renderer.targets
            out.append(t.read(t.lit)[..., :3].astype(float))
            if cues:
                kind = t.read(t.ids)[..., 1]
        finally:
            renderer.release()
    return out[0], out[1], kind


def near(image, color, tol: float = 40.0) -> np.ndarray:
    return np.linalg.norm(image - np.array(color) * 255, axis=-1) < tol


def test_outline_only_where_the_probe_is_hidden(gl, crambin):
    atom = int(np.argmax(crambin.positions[:, 2]))
    top = crambin.positions[atom]
    fx = Effects(fxaa=False)
    # the probe 2 Å under the top atom's centre, seen from above: that atom (1.7 Å) hides it
    probe = Probe(center=top - [0.0, 0.0, 2.0])
    scene = SceneState(crambin, probe=probe, effects=fx)
    camera = Camera(eye=top + [0.0, 0.0, 25.0], target=top)
    with_cues, without, kind = frames(gl, scene, camera)
    changed = np.abs(with_cues - without).max(axis=-1) > 8
    assert changed.sum() > 20 and np.all(near(with_cues, OUTLINE_COLOR, 60)[changed].mean() > 0.7)
    assert not np.any(changed & (kind == 4)), "the outline is not drawn over the visible probe"
    free = SceneState(
        crambin, probe=Probe(center=top + [0.0, 0.0, 6.0]), effects=fx
    )  # nothing hides it
    with_cues, without, _ = frames(gl, free, camera)
    assert np.array_equal(with_cues, without)


def test_ghost_tip_spring_and_force_arrow_colours(gl, crambin):
    atom = int(np.argmax(crambin.positions[:, 2]))
    top = crambin.positions[atom]
    center = top + [0.0, 0.0, crambin.vdw_radii[atom] + 1.4]
    camera = Camera(
        eye=center + [0.0, -30.0, 4.0], target=center
    )  # from the side: the arrow points up
    for force, color in ((0.2, FORCE_COLORS[0]), (0.6, FORCE_COLORS[1]), (1.5, FORCE_COLORS[2])):
        probe = Probe(
            center=center, goal=center - [0.0, 0.0, 1.0], force_n=np.array([0.0, 0.0, force])
        )
        scene = SceneState(
            crambin, probe=probe, effects=Effects(fxaa=False), force_ratings_n=(0.88, 3.3)
        )
        with_cues, without, _ = frames(gl, scene, camera)
        changed = np.abs(with_cues - without).max(axis=-1) > 8
        assert near(with_cues, color)[changed].sum() > 10, (
            force
        )  # the arrow, in the colour of its rating band
        assert near(with_cues, GHOST_COLOR, 60)[changed].sum() > 10  # the ghost tip and its spring


def test_an_arrow_at_the_edge_points_at_a_probe_off_screen(gl, crambin):
    center = crambin.positions.mean(axis=0)
    camera = Camera(eye=center + [0.0, 0.0, 60.0], target=center)
    scene = SceneState(
        crambin, probe=Probe(center=center + [200.0, 0.0, 0.0]), effects=Effects(fxaa=False)
    )
    with_cues, without, _ = frames(gl, scene, camera)
    ys, xs = np.nonzero(np.abs(with_cues - without).max(axis=-1) > 8)
    assert xs.size > 10 and xs.min() > SIZE[0] * 0.8, "at the right edge, toward the probe"
    assert abs(ys.mean() - SIZE[1] / 2) < 10


def test_touched_label_names_chain_residue_number_and_atom(crambin):
    assert touched_label(crambin, 0) == "A THR 1 N"  # 1CRN's first ATOM record
    assert touched_label(crambin, -1) is None and touched_label(None, 0) is None
