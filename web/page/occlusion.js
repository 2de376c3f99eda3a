// Which of the cube's atoms can show at all. A software rasteriser shades every pixel a
// sphere's octagon covers, hidden or not, so atoms that nearer atoms surely hide are left
// out, found on a coarse map of the picture (CELL pixels a cell):
//  - every atom holds a ball around its centre of radius r' (its radius, or less: the
//    centre's distance to the nearest face of the cube, so the ball lies inside what is drawn
//    of the atom). Through a cell that lies inside the ball's cross-section square to the
//    camera's forward axis (a disc on the picture), each ray crosses that cross-section at a
//    point p no further than rho from the centre, and p is at least r' - rho inside the ball:
//    the ray meets the atom at least that far before p, so no deeper than
//    z - (r' - rho) cos(theta) (z: the centre's depth, theta: the ray's angle to the forward
//    axis). Each cell keeps the nearest such depth of all atoms;
//  - an atom is hidden when every cell its bounding box's projection touches is covered
//    nearer than its nearest point.
// Both bounds are conservative, so no atom that shows is ever left out. Depths are distances
// along the camera's forward axis.
import { dot, sub } from "sasprobe/math.js";

const CELL = 4; // pixels

export class Occlusion {
  constructor() {
    this.map = new Float32Array(0);
  }

  // The spheres of `list` (a SphereList) that can show, into `out`; `whole`: every atom is
  // uncut (no cube), so any may hide others.
  visible(list, camera, size, cube, axes, whole, out) {
    const [w, h] = size;
    const cols = Math.ceil(w / CELL);
    const rows = Math.ceil(h / CELL);
    if (this.map.length < cols * rows) this.map = new Float32Array(cols * rows);
    const map = this.map;
    map.fill(Infinity, 0, cols * rows);
    const focal = h / 2 / Math.tan((camera.fovDeg * Math.PI) / 360);
    const { eye, right, up, back } = camera;
    const s = list.spheres;
    const n = list.count;
    const ax = [0, 1, 2].map((k) => [axes[k], axes[3 + k], axes[6 + k]]);
    // screen position (pixels, y up) of a point relative to the eye, at depth z
    const px = (v, z) => [w / 2 + (dot(v, right) / z) * focal, h / 2 + (dot(v, up) / z) * focal];

    for (let i = 0; i < n; i++) {
      const c = [s[4 * i], s[4 * i + 1], s[4 * i + 2]];
      let rho = s[4 * i + 3];
      if (!whole) {
        const rel = sub(c, cube.center);
        for (const a of ax) rho = Math.min(rho, cube.half - Math.abs(dot(rel, a)));
      }
      const v = sub(c, eye);
      const z = -dot(v, back);
      if (rho <= 0 || z - rho <= camera.near) continue;
      const [cx, cy] = px(v, z);
      const radius = (rho * focal) / z; // the cross-section's radius on the picture
      const x0 = Math.max(0, Math.ceil((cx - radius) / CELL));
      const x1 = Math.min(cols, Math.floor((cx + radius) / CELL));
      const y0 = Math.max(0, Math.ceil((cy - radius) / CELL));
      const y1 = Math.min(rows, Math.floor((cy + radius) / CELL));
      for (let y = y0; y < y1; y++) {
        const ny = Math.max(Math.abs(y * CELL - cy), Math.abs((y + 1) * CELL - cy));
        const fy = Math.max(Math.abs(y * CELL - h / 2), Math.abs((y + 1) * CELL - h / 2));
        for (let x = x0; x < x1; x++) {
          const nx = Math.max(Math.abs(x * CELL - cx), Math.abs((x + 1) * CELL - cx));
          const reach = Math.hypot(nx, ny); // pixels from the centre's projection
          if (reach >= radius) continue;
          const fx = Math.max(Math.abs(x * CELL - w / 2), Math.abs((x + 1) * CELL - w / 2));
          const cos = focal / Math.hypot(focal, fx, fy);
          const depth = z - (rho - (reach * z) / focal) * cos;
          const k = y * cols + x;
          if (depth < map[k]) map[k] = depth;
        }
      }
    }

    let kept = 0;
    for (let i = 0; i < n; i++) {
      const c = [s[4 * i], s[4 * i + 1], s[4 * i + 2]];
      const r = s[4 * i + 3];
      const v = sub(c, eye);
      const zNear = -dot(v, back) - r;
      let hidden = zNear > camera.near;
      if (hidden) {
        // the projection of the bounding box (camera-aligned) of the sphere
        let lo = [Infinity, Infinity];
        let hi = [-Infinity, -Infinity];
        for (const sz of [-1, 1]) {
          const zc = zNear + r + sz * r;
          for (const sx of [-1, 1])
            for (const sy of [-1, 1]) {
              const p = px([
                v[0] + r * (sx * right[0] + sy * up[0] - sz * back[0]),
                v[1] + r * (sx * right[1] + sy * up[1] - sz * back[1]),
                v[2] + r * (sx * right[2] + sy * up[2] - sz * back[2]),
              ], zc);
              lo = [Math.min(lo[0], p[0]), Math.min(lo[1], p[1])];
              hi = [Math.max(hi[0], p[0]), Math.max(hi[1], p[1])];
            }
        }
        const x0 = Math.max(0, Math.floor(lo[0] / CELL));
        const x1 = Math.min(cols - 1, Math.floor(hi[0] / CELL));
        const y0 = Math.max(0, Math.floor(lo[1] / CELL));
        const y1 = Math.min(rows - 1, Math.floor(hi[1] / CELL));
        for (let y = y0; y <= y1 && hidden; y++)
          for (let x = x0; x <= x1; x++)
            if (!(map[y * cols + x] < zNear)) {
              hidden = false;
              break;
            }
      }
      if (hidden) continue;
      if (kept === out.capacity) out.grow();
      out.spheres.set(s.subarray(4 * i, 4 * i + 4), 4 * kept);
      out.ids[2 * kept] = list.ids[2 * i];
      out.ids[2 * kept + 1] = list.ids[2 * i + 1];
      kept++;
    }
    out.count = kept;
    return out;
  }
}
