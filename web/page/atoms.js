// The structure as the page holds it, and the atoms the navigation cube shows.
//
// An atom is drawn when its sphere overlaps the cube (an exact sphere-box test in the cube's
// frame); it is cut by the cube's faces it crosses (bit 2k: the face at -half along axis k,
// bit 2k + 1: the one at +half), so only those planes are tested per pixel. Atoms are binned
// once into a grid of CELL Å cells, so finding the cube's atoms visits the cells the cube's
// box overlaps, not the whole structure.
import { column, dot } from "sasprobe/math.js";

const CELL = 8; // Å

export class Atoms {
  constructor(structure) {
    const { positions, radii } = structure.arrays;
    this.name = structure.header.name;
    this.sha256 = structure.header.sha256;
    this.count = structure.header.n_atoms;
    this.positions = positions;
    this.radii = radii;
    this.trace = structure.arrays.trace;
    this.traceColors = structure.arrays.trace_colors;
    this.colors = null; // Uint8Array rgb per atom, from a colors packet
    this.scheme = null;
    let maxRadius = 0;
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < this.count; i++) {
      maxRadius = Math.max(maxRadius, radii[i]);
      for (let k = 0; k < 3; k++) {
        lo[k] = Math.min(lo[k], positions[3 * i + k]);
        hi[k] = Math.max(hi[k], positions[3 * i + k]);
      }
    }
    this.maxRadius = maxRadius;
    const center = [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2);
    let reach = 0;
    for (let i = 0; i < this.count; i++) {
      const dx = positions[3 * i] - center[0];
      const dy = positions[3 * i + 1] - center[1];
      const dz = positions[3 * i + 2] - center[2];
      reach = Math.max(reach, Math.hypot(dx, dy, dz) + radii[i]);
    }
    this.bounds = { center, radius: reach };
    this._bin(lo, hi);
  }

  _bin(lo, hi) {
    this.origin = lo;
    this.dims = [0, 1, 2].map((k) => Math.max(1, Math.ceil((hi[k] - lo[k]) / CELL + 1e-6)));
    const [nx, ny, nz] = this.dims;
    const cellOf = new Int32Array(this.count);
    const counts = new Int32Array(nx * ny * nz + 1);
    for (let i = 0; i < this.count; i++) {
      const c = this._cell(i);
      cellOf[i] = c;
      counts[c + 1]++;
    }
    for (let c = 0; c < nx * ny * nz; c++) counts[c + 1] += counts[c];
    this.cellStart = counts;
    this.cellAtoms = new Int32Array(this.count);
    const fill = counts.slice(0, nx * ny * nz);
    for (let i = 0; i < this.count; i++) this.cellAtoms[fill[cellOf[i]]++] = i;
  }

  _cell(i) {
    const [nx, ny, nz] = this.dims;
    const p = this.positions;
    const ix = Math.min(nx - 1, Math.floor((p[3 * i] - this.origin[0]) / CELL));
    const iy = Math.min(ny - 1, Math.floor((p[3 * i + 1] - this.origin[1]) / CELL));
    const iz = Math.min(nz - 1, Math.floor((p[3 * i + 2] - this.origin[2]) / CELL));
    return (iz * ny + iy) * nx + ix;
  }

  // The atoms the cube ({center, half}, turned by `axes`) shows, into `out`:
  // {count, spheres: Float32Array(4 a atom), ids: Int32Array(2 a atom: atom, face bits)}.
  inCube(cube, axes, out) {
    const a = [column(axes, 0), column(axes, 1), column(axes, 2)];
    const h = cube.half;
    const reach = [0, 1, 2].map(
      (k) => h * (Math.abs(a[0][k]) + Math.abs(a[1][k]) + Math.abs(a[2][k])) + this.maxRadius,
    );
    const first = [0, 1, 2].map((k) =>
      Math.max(0, Math.floor((cube.center[k] - reach[k] - this.origin[k]) / CELL)));
    const last = [0, 1, 2].map((k) =>
      Math.min(this.dims[k] - 1, Math.floor((cube.center[k] + reach[k] - this.origin[k]) / CELL)));
    const p = this.positions;
    const [nx, ny] = this.dims;
    let n = 0;
    for (let iz = first[2]; iz <= last[2]; iz++)
      for (let iy = first[1]; iy <= last[1]; iy++) {
        const row = (iz * ny + iy) * nx;
        const begin = this.cellStart[row + first[0]];
        const end = this.cellStart[row + last[0] + 1];
        for (let j = begin; j < end; j++) {
          const i = this.cellAtoms[j];
          const rx = p[3 * i] - cube.center[0];
          const ry = p[3 * i + 1] - cube.center[1];
          const rz = p[3 * i + 2] - cube.center[2];
          const r = this.radii[i];
          let gap2 = 0;
          let faces = 0;
          for (let k = 0; k < 3; k++) {
            const q = rx * a[k][0] + ry * a[k][1] + rz * a[k][2];
            const g = q < -h ? q + h : q > h ? q - h : 0;
            gap2 += g * g;
            if (q - r < -h) faces |= 1 << (2 * k);
            if (q + r > h) faces |= 1 << (2 * k + 1);
          }
          if (gap2 > r * r) continue;
          if (n === out.capacity) out.grow();
          const s = out.spheres;
          s[4 * n] = p[3 * i];
          s[4 * n + 1] = p[3 * i + 1];
          s[4 * n + 2] = p[3 * i + 2];
          s[4 * n + 3] = r;
          out.ids[2 * n] = i;
          out.ids[2 * n + 1] = faces;
          n++;
        }
      }
    out.count = n;
    return out;
  }
}

// A growable list of drawn spheres: centre and radius, atom id and face bits.
export class SphereList {
  constructor(capacity = 1024) {
    this.capacity = capacity;
    this.count = 0;
    this.spheres = new Float32Array(4 * capacity);
    this.ids = new Int32Array(2 * capacity);
  }

  grow() {
    const spheres = new Float32Array(8 * this.capacity);
    const ids = new Int32Array(4 * this.capacity);
    spheres.set(this.spheres);
    ids.set(this.ids);
    this.capacity *= 2;
    this.spheres = spheres;
    this.ids = ids;
  }
}

// The six faces of the cube as planes (n, w) keeping n . x + w >= 0, in the order of the
// face bits above.
export function cubePlanes(cube, axes) {
  const planes = [];
  for (let k = 0; k < 3; k++) {
    const n = column(axes, k);
    const c = dot(n, cube.center);
    planes.push([n[0], n[1], n[2], -(c - cube.half)]);
    planes.push([-n[0], -n[1], -n[2], c + cube.half]);
  }
  return planes;
}
