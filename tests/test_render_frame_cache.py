"""The frame planner (render/frame_planner.py): frames in which only the probe moved, drawn
from the kept molecule layer, equal a full redraw of the same scene; progressive AO keeps
accumulating while only the probe moves; anything but the probe invalidates the layer,
including scene and settings fields that do not exist yet."""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np
import pytest
from sasprobe.molecule import DEFAULT_PROBE_RADIUS, UniformGrid, load_structure
from sasprobe.render.camera import Camera
from sasprobe.render.frame_planner import LIT, FrameKind, FramePlan, state_key
from sasprobe.render.gbuffer_export import gbuffer_arrays
from sasprobe.render.gl.targets import KIND_PROBE
from sasprobe.render.gl.textures import read_image, release_framebuffers
from sasprobe.render.lighting.settings import AOSettings, LightingSettings, ShadingSettings
from sasprobe.render.passes.fxaa import FxaaPass
from sasprobe.render.rects import union_rect
from sasprobe.render.renderer import Renderer
from sasprobe.render.scene_state import Effects, Mark, NavCube, Probe, SceneState
from sasprobe.render.workspace_view import workspace_camera

from tests.support.lighting import probe_on_surface

pytestmark = pytest.mark.needs_gl(430)

DIRECTION = np.array([0.2, 0.3, 1.0]) / np.linalg.norm([0.2, 0.3, 1.0])
LIGHT = -np.array([0.45, 0.8, 0.4]) / np.linalg.norm([0.45, 0.8, 0.4])


def probe_path(structure) -> list[np.ndarray | None]:
    """The probe coming in from 2.5 Å off the SAS, touching it, sliding over it, then leaving
    the picture (None: no probe)."""
    path = [probe_on_surface(structure, DIRECTION, lift=lift) for lift in (2.5, 1.5, 0.5, 0.0)]
    for turn in (0.15, 0.3, 0.45):
        side = DIRECTION + turn * np.array([1.0, -0.4, 0.0])
        path.append(probe_on_surface(structure, side, lift=0.0))
    return path + [None]


def workspace_path(structure) -> list[np.ndarray | None]:
    """As probe_path, in a large structure's workspace view: coming in 5 Å along the surface's
    normal, touching, then moving a few Å across the picture at the touch's depth (the probe
    plane holds while the probe keeps its depth), then leaving."""
    path = [grid_surface(structure, DIRECTION, lift=lift) for lift in (5.0, 2.5, 0.5, 0.0)]
    return (
        path
        + [path[-1] + offset for offset in ([1.0, 0.0, 0.0], [2.0, -0.5, 0.0], [3.0, -1.0, 0.0])]
        + [None]
    )


def grid_surface(structure, direction, lift=0.0):
    """A probe centre on the SAS as probe_on_surface finds it, through the grid (a large
    structure's brute force would not fit in memory), lifted `lift` Å away from the atom
    whose expanded sphere it lies on (along the direction a groove can swallow a lift)."""
    grid = UniformGrid(structure.positions, structure.expanded_radii(DEFAULT_PROBE_RADIUS))
    direction = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    centre = structure.positions.mean(axis=0)
    far = float(np.linalg.norm(grid.upper - grid.origin))
    for t in np.arange(far, 0.0, -0.05):  # inward: the first point inside an expanded sphere
        if grid.spheres_within(centre + t * direction, 0.0).size:
            point = centre + (t + 0.05) * direction
            atom = grid.nearest_to_point(point, 1)[0]
            normal = (point - structure.positions[atom]) / np.linalg.norm(
                point - structure.positions[atom]
            )
            return point + lift * normal
    raise AssertionError("no surface along the direction")


def sas_gap(structure, point) -> float:
    """Distance of a probe centre from the SAS (negative inside)."""
    return float(
        np.min(
            np.linalg.norm(structure.positions - point, axis=1)
            - structure.vdw_radii
            - DEFAULT_PROBE_RADIUS
        )
    )


def make_renderer(gl, structure, size, settings, cache, setup="none"):
    scene = SceneState(structure)
    scene.light_direction = LIGHT
    for name, on in settings.effects().items():
        setattr(scene.effects, name, on)
    centre = structure.positions.mean(axis=0)
    if setup == "cube":
        scene.nav_cube = NavCube(center=centre + [2.0, -1.0, 4.0], half=10.0)
    elif (
        setup == "probe-plane"
    ):  # the workspace view's: it cuts the molecule layer where the probe is
        scene.effects.probe_plane = True
    elif (
        setup == "workspace"
    ):  # the daemon's default cube (14 Å) about the touch, the camera framing it
        scene.effects.probe_plane = True
        scene.nav_cube = NavCube(center=grid_surface(structure, DIRECTION), half=14.0)
    elif setup == "plane":
        n = -np.array([1.0, 0.2, 0.5]) / np.linalg.norm([1.0, 0.2, 0.5])
        scene.clip_planes = [np.array([*n, -float(n @ centre) + 2.0])]
    renderer = Renderer(gl, scene, size, frame_cache=cache)
    renderer.install_lighting(settings)
    if setup == "workspace":
        return renderer, workspace_camera(scene.nav_cube, size[0] / size[1])
    c, r = scene.bounding_sphere()
    fit = (
        2.0 if setup == "far" else 0.8
    )  # far: the probe light's reach overhangs the molecule's pixels
    return renderer, Camera.fitted(c, r * fit, size[0] / size[1], direction=DIRECTION)


def agreement(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels whose every channel agrees within 2/255."""
    return float((np.abs(a.astype(int) - b.astype(int)).max(axis=2) <= 2).mean())


CASES = [
    (
        "1crn",
        (160, 120),
        LightingSettings(),
        "none",
    ),  # the default lighting: hard shadows, analytic AO
    ("1crn", (160, 120), LightingSettings(), "far"),
    (
        "1crn",
        (160, 120),
        LightingSettings(shadows="soft", edges="both", ao=AOSettings(k=16)),
        "cube",
    ),
    (
        "1crn",
        (160, 120),
        LightingSettings(shadows="precomputed", ao=AOSettings(mode="precomputed")),
        "plane",
    ),
    ("1tii", (200, 150), LightingSettings(), "none"),
    ("1tii", (200, 150), LightingSettings(), "probe-plane"),
    ("1aon", (160, 120), LightingSettings(), "workspace"),
    ("1aon", (160, 120), LightingSettings(shadows="soft", edges="both"), "workspace"),
]


@pytest.mark.parametrize(
    "sid, size, settings, setup", CASES, ids=[f"{c[0]}-{c[3]}-{c[2].shadows}" for c in CASES]
)
def test_cached_frames_equal_a_full_redraw(gl, reference_by_id, sid, size, settings, setup):
    structure = load_structure(reference_by_id[sid].path, keep_water=True)
    path = workspace_path(structure) if setup == "workspace" else probe_path(structure)
    gaps = [sas_gap(structure, p) for p in path if p is not None]
    assert gaps[0] > 2.0 and min(abs(g) for g in gaps[3:]) < 0.06  # it comes in and touches
    if setup in (
        "probe-plane",
        "workspace",
    ):  # the plane steps with the probe; standing still, the cut layer is kept and used
        path += [path[-2]] * 3
    cached, camera = make_renderer(gl, structure, size, settings, cache=True, setup=setup)
    full, full_camera = make_renderer(gl, structure, size, settings, cache=False, setup=setup)
    planes = []  # the planes in effect, frame by frame
    shaded, antialiased = (
        [],
        [],
    )  # the fractions of the pixels each frame shaded and antialiased again
    try:
        for center in path:
            for r in (cached, full):
                r.scene.probe = (
                    None if center is None else Probe(center=center.copy(), touched_atom=3)
                )
            planes.append(cached.scene.active_planes(camera).tobytes())
            cached.render(camera)
            full.render(full_camera)
            a, b = cached.read_image(), full.read_image()
            assert agreement(a, b) >= 0.999, (sid, setup, center)
            plan = cached.last_frame.plan
            for fractions, rect in (
                (shaded, plan.region(LIT)),
                (antialiased, union_rect(*FxaaPass.regions(plan))),
            ):
                fractions.append(0.0 if rect is None else rect[2] * rect[3] / (size[0] * size[1]))
            kinds = cached.targets.read(cached.targets.ids)[..., 1]
            assert (kinds == KIND_PROBE).any() == (
                center is not None
            )  # the probe is in the picture
            # the terms too, off the probe's own pixels (which the shading does not light)
            ga, gb = gbuffer_arrays(cached), gbuffer_arrays(full)
            for layer in ("shadow_dir", "shadow_probe", "ao"):
                assert (layer in ga) == (layer in gb)
                if layer in ga:
                    off_probe = ga["kind"] != KIND_PROBE
                    assert np.abs(ga[layer] - gb[layer])[off_probe].max() <= 1e-5, (
                        sid,
                        setup,
                        layer,
                    )
        if setup in (
            "probe-plane",
            "workspace",
        ):  # drawn again only when the plane stepped, kept once it held a frame
            changes = sum(a != b for a, b in zip(planes, planes[1:]))
            held = sum(a == b == c for a, b, c in zip(planes, planes[1:], planes[2:]))
            counts = cached.planner.layer_counts()
            assert counts["drawn"] >= 1 + changes and counts["kept"] >= held >= 1
            assert counts["kept"] + counts["drawn"] == len(path)
        else:
            assert cached.planner.layer_counts() == {
                "kept": len(path) - 1,
                "drawn": 1,
            }  # the layer held throughout
        assert shaded[0] == antialiased[0] == 1.0
        if setup == "far":  # only the molecule's pixels within the probe's reach were shaded again
            assert max(shaded[1:]) < 0.5, shaded
        if (
            setup == "workspace"
        ):  # the trace around the cube is not shaded again: the probe does not light it
            assert min(shaded[1:]) < 0.6, shaded
        if sid == "1tii" and setup == "none":  # the rest of the picture was kept, and still agrees
            assert max(shaded[1:]) < 0.9 and max(antialiased[1:]) < 0.95, (shaded, antialiased)
        assert full.planner is None
    finally:
        cached.release()
        full.release()


@pytest.mark.parametrize(
    "sid, fit, probe_range",
    [("1tii", 0.5, 6.0), ("1crn", 1.6, 20.0)],
    ids=["1tii-fills", "1crn-amid"],
)
def test_antialiasing_redone_in_part_equals_antialiasing_the_whole_frame(
    gl, reference_by_id, sid, fit, probe_range
):
    """FXAA run again only where the lit picture changed, and where the probe's cues are and
    were, gives what FXAA over the whole lit picture gives, bit for bit: the probe sliding
    with its ghost, spring and force arrow, then leaving. 1TII fills the frame and the probe
    light reaches 6 Å, so the redone rectangle's edges cross the atoms' outlines, and the
    cues reach beyond what the shading does again; 1CRN lies amid the background, most of
    which its changed surfaces' rectangle holds, and FXAA runs there only near the surfaces
    (the near-surface mask)."""
    structure = load_structure(reference_by_id[sid].path, keep_water=True)
    size = (200, 150)
    scene = SceneState(structure)
    scene.force_ratings_n = (3.3, 8.5)
    renderer = Renderer(gl, scene, size, shading=ShadingSettings(probe_range=probe_range))
    renderer.install_lighting(LightingSettings())
    c, r = scene.bounding_sphere()
    camera = Camera.fitted(c, r * fit, size[0] / size[1], direction=DIRECTION)
    # per frame, the fraction of the pixels FXAA ran near the surfaces only that the mask left out
    skipped = []
    whole = FxaaPass(gl, renderer.programs)
    picture = gl.texture(size, 4)
    out = gl.framebuffer([picture])
    redone = []
    try:
        for k, center in enumerate(probe_path(structure)):
            scene.probe = (
                None
                if center is None
                else Probe(
                    center=center,
                    touched_atom=3,
                    goal=center + (k % 3) * np.array([6.0, -4.5, 3.0]),
                    force_n=np.array([1.5 * k, 1.0 + k, -0.5]),
                )
            )  # the ghost and the arrow reach beyond the light
            frame = renderer.render(camera)
            whole.run(dataclasses.replace(frame, plan=FramePlan(size=size), output_fbo=out))
            assert np.array_equal(renderer.read_image(), read_image(out, size)), k
            fxaa = renderer.pass_named("fxaa")
            whole_rect, near_rect = FxaaPass.regions(frame.plan)
            rect = union_rect(whole_rect, near_rect)
            redone.append(0.0 if rect is None else rect[2] * rect[3] / (size[0] * size[1]))
            if frame.plan.molecule_kept and near_rect is not None:
                x, y, w, h = near_rect
                mask = np.frombuffer(fxaa.near_surfaces.depth.read(), dtype=np.float32).reshape(
                    size[1], size[0]
                )
                skipped.append(float((mask[y : y + h, x : x + w] > 0.5).mean()))
        assert (
            renderer.planner.counts[FrameKind.KEPT] == len(redone) - 1
            and redone[0] == 1.0
            and max(redone[1:]) < 0.75
        ), redone
        if (
            sid == "1crn"
        ):  # the mask left out much of what the rectangle of the changed surfaces holds
            assert skipped and min(skipped) > 0.2, skipped
    finally:
        whole.release()
        release_framebuffers(gl, out)
        picture.release()
        renderer.release()


def test_a_probe_that_moved_leaves_no_trace(gl, crambin):
    """After the probe has moved away, the pixels it covered show the molecule layer again,
    bit for bit as a renderer that never drew it there."""
    settings = LightingSettings()
    r, camera = make_renderer(gl, crambin, (160, 120), settings, cache=True)
    fresh, fresh_camera = make_renderer(gl, crambin, (160, 120), settings, cache=True)
    try:
        first, last = probe_path(crambin)[3], probe_path(crambin)[6]
        r.scene.probe = Probe(center=first)
        r.render(camera)
        seen = r.read_image()
        r.scene.probe = Probe(center=last)
        r.render(camera)
        fresh.scene.probe = Probe(center=last)
        fresh.render(fresh_camera)
        assert r.planner.counts[FrameKind.KEPT] == 1
        assert np.array_equal(r.read_image(), fresh.read_image())
        assert not np.array_equal(seen, r.read_image())
    finally:
        r.release()
        fresh.release()


def test_progressive_ao_keeps_accumulating_while_only_the_probe_moves(gl, crambin):
    """Ray-traced AO of the molecule does not depend on the probe: its samples keep adding up
    while the probe moves, and after the same number of frames the picture equals one where
    the probe stood at its last place all along."""
    settings = LightingSettings(shadows="off", ao=AOSettings(mode="rt", rt_spp=2))
    path = [p for p in probe_path(crambin) if p is not None]
    moving, camera = make_renderer(gl, crambin, (128, 96), settings, cache=True)
    still, still_camera = make_renderer(gl, crambin, (128, 96), settings, cache=True)
    try:
        for i, center in enumerate(path):
            moving.scene.probe = Probe(center=center)
            moving.render(camera)
            still.scene.probe = Probe(center=path[-1])
            still.render(still_camera)
            assert moving.lighting.ao.samples == 2 * (i + 1)
        assert np.array_equal(moving.read_image(), still.read_image())
        camera.orbit(np.array([0.0, 1.0, 0.0]), 0.1)  # the camera turns: accumulation starts over
        moving.render(camera)
        assert moving.lighting.ao.samples == 2
    finally:
        moving.release()
        still.release()


def test_a_turning_camera_draws_whole_frames_and_the_layer_is_kept_once_it_stops(gl, crambin):
    """While the layer's key changes frame after frame (the camera turning) the frames are
    drawn whole, as without the cache, and equal a full redraw; the first frame after a
    held one still keeps its layer (a single change: the probe plane stepping), and once
    the camera stops the layer is drawn again and then used."""
    settings = LightingSettings()
    cached, camera = make_renderer(gl, crambin, (128, 96), settings, cache=True)
    full, full_camera = make_renderer(gl, crambin, (128, 96), settings, cache=False)
    try:
        states = []  # per frame: hit (True), layer drawn and kept (False), drawn whole (None)
        for k in range(9):
            if 2 <= k <= 5:  # turning for four frames, then still
                for c in (camera, full_camera):
                    c.orbit(np.array([0.0, 1.0, 0.0]), 0.05)
            for r in (cached, full):
                r.scene.probe = Probe(center=probe_path(crambin)[3 + k % 4])
            cached.render(camera)
            full.render(full_camera)
            kind = cached.last_frame.plan.kind
            states.append(
                True if kind == FrameKind.KEPT else (None if kind == FrameKind.WHOLE else False)
            )
            assert agreement(cached.read_image(), full.read_image()) >= 0.999, k
        assert states == [False, True, False, None, None, None, False, True, True], states
    finally:
        cached.release()
        full.release()


# ------------------------------------------------------------------ the key
def _changed(value):
    """A different value of the same kind (for the generic invalidation test)."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, (int, float)):
        return value + 1
    if isinstance(value, tuple):
        return tuple(_changed(v) for v in value)
    if isinstance(value, np.ndarray):
        return value + 0.5
    raise TypeError(type(value))


def test_every_effect_camera_and_setting_but_the_probe_invalidates_the_layer(gl, crambin):
    settings = LightingSettings()
    r, camera = make_renderer(gl, crambin, (64, 48), settings, cache=True)
    try:
        r.scene.probe = Probe(center=probe_path(crambin)[3])
        r.render(camera)

        def misses_after(change) -> int:
            before = r.planner.layer_counts()["drawn"]
            change()
            r.render(camera)
            return r.planner.layer_counts()["drawn"] - before

        assert (
            misses_after(lambda: setattr(r.scene, "probe", Probe(center=probe_path(crambin)[5])))
            == 0
        )
        assert misses_after(lambda: setattr(r.scene.probe, "touched_atom", 7)) == 0
        for f in dataclasses.fields(Effects):
            value = getattr(r.scene.effects, f.name)
            changed = (
                (not value)
                if isinstance(value, bool)
                else ("polymer" if value != "polymer" else "element")
            )
            assert misses_after(lambda f=f, v=changed: setattr(r.scene.effects, f.name, v)) == 1, (
                f.name
            )
        assert (
            misses_after(
                lambda: setattr(r.scene, "lights_follow_camera", not r.scene.lights_follow_camera)
            )
            == 1
        )
        assert (
            misses_after(
                lambda: r.scene.marks.append(Mark(1, "pocket", tuple(crambin.positions[2])))
            )
            == 1
        )
        assert (
            misses_after(lambda: setattr(r.scene, "light_direction", -r.scene.light_direction)) == 1
        )
        assert (
            misses_after(
                lambda: setattr(r.scene, "nav_cube", NavCube(crambin.positions[0].copy(), 6.0))
            )
            == 1
        )
        assert misses_after(lambda: setattr(r.scene.nav_cube, "half", 7.0)) == 1
        assert (
            misses_after(lambda: r.scene.clip_planes.append(np.array([1.0, 0.0, 0.0, -9.0]))) == 1
        )
        assert misses_after(lambda: setattr(r.scene, "probe_radius", 1.2)) == 1
        for name in ("eye", "target", "up", "fov_y"):
            assert (
                misses_after(lambda n=name: setattr(camera, n, _changed(getattr(camera, n)))) == 1
            ), name
        shading = r.pass_named("shading").settings
        for f in dataclasses.fields(shading):
            assert (
                misses_after(
                    lambda f=f: setattr(shading, f.name, _changed(getattr(shading, f.name)))
                )
                == 1
            ), f.name
        lighting = r.lighting
        assert misses_after(lighting.cycle_ao_mode) == 1
        assert (
            misses_after(
                lambda: setattr(lighting, "settings", replace(lighting.settings, samples=3))
            )
            == 1
        )
        assert misses_after(lambda: r.resize((72, 48))) == 1
        assert misses_after(lambda: r.set_sphere_mode("sprite")) == 1
        assert (
            misses_after(lambda: None) == 1
        )  # after a run of changes the layer is drawn again once the key holds
        assert misses_after(lambda: None) == 0
    finally:
        r.release()


def test_the_key_covers_fields_added_later():
    """A field another part of the program adds to the scene (a colour scheme, say) is in the
    key without being listed anywhere; the probe alone is left out."""

    @dataclasses.dataclass
    class ExtendedScene(SceneState):
        color_scheme: str = "cpk"
        background: tuple = (0.0, 0.0, 0.0)

    from sasprobe.molecule import load_default

    scene = ExtendedScene(load_default())
    key = state_key(scene, skip=("probe",))
    assert state_key(replace(scene, color_scheme="chain"), skip=("probe",)) != key
    assert state_key(replace(scene, background=(1.0, 1.0, 1.0)), skip=("probe",)) != key
    assert state_key(replace(scene, probe=Probe(np.zeros(3))), skip=("probe",)) == key
    assert state_key(replace(scene, effects=Effects(shadows=True)), skip=("probe",)) != key
    assert state_key(AOSettings(patch=9)) != state_key(AOSettings())
    # settings (frozen) have their keys found once: the same for equal ones, asked again or not
    assert (
        state_key(AOSettings(patch=9))
        == state_key(AOSettings(patch=9))
        != state_key(AOSettings(patch=10))
    )
    assert state_key(LightingSettings(ao=AOSettings(patch=9))) != state_key(LightingSettings())

    @dataclasses.dataclass(frozen=True)
    class Held:  # frozen, but an array can change in place: found field by field every time
        values: np.ndarray

    held = Held(np.zeros(2))
    before = state_key(held)
    held.values[0] = 1.0
    assert state_key(held) != before
