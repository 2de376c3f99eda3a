// The workspace view's camera, as protocol/view.py defines it (the bridge sends its numbers):
// it looks along -(third column) of the view's axes with the second column up, from the
// distance where a sphere of frame_radius cube half edges around the cube's centre, grown by
// fit_margin, just fits the narrower field of view. The page may turn and zoom its own view
// (the daemon's mapping stays as it is: a page sends the daemon nothing); R resets it.
import {
  IDENTITY3, add, column, cross, length, mul3, mul4, normalize, perspective, rotation,
  scale, sub, viewMatrix,
} from "sasprobe/math.js";

export class ViewCamera {
  constructor(conventions) {
    this.conventions = conventions;
    this.reset();
  }

  reset() {
    this.turn = IDENTITY3; // the page's own turn (row-major), applied to the view's axes
    this.zoom = 1;
  }

  // A drag of (dx, dy) in NDC: the molecule turns with the pointer, the camera the other way.
  orbit(basis, dx, dy) {
    const angle = Math.hypot(dx, dy) * Math.PI * 0.5;
    if (angle === 0) return;
    // the axis in the view plane perpendicular to the drag, in the molecule frame
    const axis = add(scale(basis.up, -dx), scale(basis.right, dy));
    this.turn = mul3(rotation(axis, -angle), this.turn);
  }

  zoomBy(factor) {
    this.zoom = Math.min(Math.max(this.zoom * factor, 0.2), 20);
  }

  // The camera framing `cube` ({center, half}) with the view's `axes` (row-major 3x3), in a
  // picture of `aspect`; `bounds` ({center, radius}) holds everything drawn (near and far).
  frame(cube, axes, aspect, bounds) {
    const { fov_deg: fovDeg, fit_margin: margin, frame_radius: frameRadius } = this.conventions;
    const turned = mul3(this.turn, axes);
    const back = normalize(column(turned, 2));
    const right = normalize(cross(column(turned, 1), back));
    const up = cross(back, right);
    const half = (fovDeg * Math.PI) / 360;
    const halfX = Math.atan(Math.tan(half) * aspect);
    const radius = Math.max(frameRadius * cube.half * this.zoom, 1e-3);
    const distance = (radius / Math.sin(Math.min(half, halfX))) * margin;
    const eye = add(cube.center, scale(back, distance));
    const d = length(sub(eye, bounds.center));
    const near = Math.max(d - bounds.radius, bounds.radius * 1e-3);
    const far = Math.max(d + bounds.radius, near * 2);
    const view = viewMatrix(right, up, back, eye);
    const proj = perspective((fovDeg * Math.PI) / 180, aspect, near, far);
    return {
      eye, target: cube.center, right, up, back, fovDeg, aspect, near, far,
      view, proj, viewproj: mul4(proj, view),
      // the direction a view-frame vector has in the molecule frame
      toWorld: (v) => add(add(scale(right, v[0]), scale(up, v[1])), scale(back, v[2])),
    };
  }
}
