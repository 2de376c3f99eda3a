"""The workspace view: a camera that frames the navigation cube, looking along the device's -z.

The device frame is the camera frame (the convention of CHAI3D and OpenHaptics
applications): the camera's right, up and backward axes are the cube's axes, which are
the device's x, y and z in the molecule frame, so pushing the arm right moves the probe
right on screen, lifting it moves it up and pulling it toward you brings it closer. The
camera frames the cube (not the molecule) and follows it as it drifts. Turning the view
(a drag) turns the cube's axes; the turn goes to the daemon (control `view`), whose
workspace mapping turns with it and which publishes the turned axes back in its scene,
so hand and eye stay aligned. While a drag is under way the window draws the turn it
has sent, until the daemon's scene carries it.

The overview frames the whole molecule from the same direction, and can be turned freely
without touching the daemon (the hand's frame stays the workspace view's). `Tab` in the
window switches between the two.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
from sasprobe.protocol.view import FRAME_RADIUS
from sasprobe.render.camera import DEFAULT_FOV, Camera

WORKSPACE, OVERVIEW = "workspace", "overview"
VIEWS = (WORKSPACE, OVERVIEW)
TURN_SEND_S = 0.05  # a turn under way goes to the daemon at most this often
AXES_MATCH = 1e-6  # the daemon's axes equal the ones sent (its rotation is re-orthonormalised)


def workspace_camera(
    cube,
    aspect: float,
    zoom: float = 1.0,
    axes: np.ndarray | None = None,
    fov_y: float = DEFAULT_FOV,
) -> Camera:
    """The camera framing `cube` along -axes[:, 2] with axes[:, 1] up (default: the cube's axes);
    `zoom` > 1 moves it back."""
    axes = cube.axes if axes is None else axes
    return Camera.fitted(
        cube.center,
        FRAME_RADIUS * cube.half * zoom,
        aspect,
        fov_y=fov_y,
        direction=axes[:, 2],
        up=axes[:, 1],
    )


def overview_camera(scene, aspect: float, axes: np.ndarray, fov_y: float = DEFAULT_FOV) -> Camera:
    """What the picture shows of the whole molecule — with a cube, the cube's atoms and the
    backbone trace of the rest; without, every atom — and the probe, seen from the workspace
    view's direction and framed as tightly as the picture allows (Camera.framing: their
    bounding sphere would leave them a third of the picture)."""
    s = scene.structure
    cube = scene.active_cube()
    trace = np.concatenate(s.backbone) if s.backbone else np.zeros(0, dtype=np.int64)
    if cube is None or trace.size == 0:
        centers, radii = [s.positions], [s.vdw_radii]
    else:  # the cube's atoms lie within the cube grown by their radius
        centers, radii = (
            [s.positions[trace], cube.corners()],
            [np.zeros(trace.size), np.full(8, s.vdw_radii.max())],
        )
    if scene.probe is not None:
        centers.append(scene.probe.center[None, :])
        radii.append(np.array([scene.probe.radius]))
    return Camera.framing(
        np.concatenate(centers),
        np.concatenate(radii),
        aspect,
        fov_y=fov_y,
        direction=axes[:, 2],
        up=axes[:, 1],
    )


def tilted_axes(axes: np.ndarray, degrees: float) -> np.ndarray:
    """The axes turned about their x axis so that the view looks `degrees` further down from
    above: the cube, which the workspace view sees face on with the molecule behind it, is
    then seen on the molecule (the trace is hidden over the cube's projection)."""
    a = np.radians(degrees)
    x, y, z = axes[:, 0], axes[:, 1], axes[:, 2]
    return np.column_stack([x, np.cos(a) * y - np.sin(a) * z, np.sin(a) * y + np.cos(a) * z])


def turned_axes(axes: np.ndarray, p0: tuple[float, float], p1: tuple[float, float]) -> np.ndarray:
    """The cube's axes after an arcball drag from p0 to p1 (NDC): the molecule turns with the
    pointer, so the camera, and with it the device frame, turns the other way."""
    camera = Camera(eye=axes[:, 2], target=np.zeros(3), up=axes[:, 1])
    camera.arcball(p0, p1)
    return camera.basis()


class WorkspaceView:
    """Which view is shown, and the workspace view's zoom and turn under way."""

    def __init__(
        self,
        mode: str = WORKSPACE,
        send_view: Callable[[np.ndarray], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if mode not in VIEWS:
            raise ValueError(f"view must be one of {', '.join(VIEWS)}, got {mode!r}")
        self.mode = mode
        self.zoom = 1.0
        self.send_view = send_view  # None: nobody to tell (standalone), the turn stays local
        self._clock = clock
        # Axes sent (or to send) that the daemon has not shown yet.
        self._turning: np.ndarray | None = None
        self._last_sent = -math.inf
        self._local_axes: np.ndarray | None = None  # standalone: the turn itself

    @property
    def workspace(self) -> bool:
        return self.mode == WORKSPACE

    def toggle(self) -> str:
        self.mode = OVERVIEW if self.mode == WORKSPACE else WORKSPACE
        return self.mode

    def axes(self, daemon_axes: np.ndarray | None) -> np.ndarray:
        """The axes to draw with: a turn under way, else the daemon's (or the local turn)."""
        if self._turning is not None:
            if daemon_axes is not None and np.max(np.abs(daemon_axes - self._turning)) < AXES_MATCH:
                self._turning = None  # the daemon has it
            else:
                return self._turning
        if daemon_axes is not None:
            return daemon_axes
        return self._local_axes if self._local_axes is not None else np.eye(3)

    def camera(self, scene, aspect: float, daemon_axes: np.ndarray | None) -> Camera | None:
        """The workspace camera for this frame (None: no cube to frame, or the overview)."""
        if not self.workspace or scene.nav_cube is None:
            return None
        return workspace_camera(scene.nav_cube, aspect, self.zoom, self.axes(daemon_axes))

    def turn(self, daemon_axes: np.ndarray | None, p0, p1) -> None:
        """A drag in the workspace view: turn the axes and tell the daemon (throttled: end_turn
        sends the last one)."""
        axes = turned_axes(self.axes(daemon_axes), p0, p1)
        if self.send_view is None:
            self._local_axes = axes
            return
        self._turning = axes
        now = self._clock()
        if now - self._last_sent >= TURN_SEND_S:
            self._last_sent = now
            self.send_view(axes)

    def end_turn(self) -> None:
        """The drag ended: the last turn goes out whatever the throttle says."""
        if self._turning is not None and self.send_view is not None:
            self.send_view(self._turning)
            self._last_sent = self._clock()

    def zoom_by(self, factor: float) -> None:
        self.zoom = float(np.clip(self.zoom * factor, 0.2, 20.0))

    def reset(self) -> None:
        self.zoom = 1.0
