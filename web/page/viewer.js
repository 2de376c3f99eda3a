// The workspace view both pages show: the structure, the session's scene and its newest pose
// turned into a frame (the cube's atoms, the trace, the probe, the cube's edges, the force
// arrow), the text over it, the page's own turn and zoom, and the test hooks.
//
// A source (live.js, replay.js) hands the viewer what arrives: `setLook` (the bridge's
// conventions and colours), `setStructure` and `setColors` (packets), `setScene` and
// `setPose`; the viewer draws on every animation frame and tells the source which pose it
// drew (`source.drawn(seq)`).
import { Atoms, SphereList, cubePlanes } from "sasprobe/atoms.js";
import { ViewCamera } from "sasprobe/camera.js";
import { Occlusion } from "sasprobe/occlusion.js";
import { Overlay } from "sasprobe/overlay.js";
import { Renderer } from "sasprobe/renderer.js";
import {
  IDENTITY3, add, apply3, column, cross, length, normalize, project, scale, sub,
} from "sasprobe/math.js";

const FLAG_CONTACT = 1;
const FLAG_DRIFTING = 8;
const FLAG_CLUTCHED = 32;
const FPS_WINDOW_MS = 1000;
const DRAW_TIMES = 200; // frames whose draw times state() summarises

function rowsToMatrix(rows) {
  return [...rows[0], ...rows[1], ...rows[2]];
}

export class Viewer {
  constructor(root, source) {
    this.source = source;
    this.canvas = root.querySelector("canvas");
    this.overlay = new Overlay(root);
    try {
      this.renderer = new Renderer(this.canvas);
    } catch (error) {
      this.renderer = null;
      const reason = String(error.message || error);
      this.overlay.fatal(reason === "no WebGL2"
        ? "This page needs WebGL2, which this browser does not offer."
        : `The page cannot draw: ${reason}`);
      return;
    }
    this.look = null;
    this.atoms = null;
    this.scene = null;
    this.pose = null;
    this.camera = null;
    this.cubeKey = "";
    this.viewKey = "";
    this.list = new SphereList(); // the atoms the cube holds
    this.shown = new SphereList(); // those of them that can show from this camera
    this.occlusion = new Occlusion();
    this.frames = 0;
    this.drawnSeq = -1;
    this.lastFrame = null;
    this.frameTimes = [];
    this.drawTimes = null; // the last frames' draw times (ms), once timeDraws() asks for them
    this._input();
  }

  get ok() {
    return this.renderer !== null;
  }

  setLook(hello) {
    this.look = hello;
    this.camera = new ViewCamera(hello.view);
  }

  setStructure(packet) {
    this.atoms = new Atoms(packet);
    this.renderer.setStructure(this.atoms);
    this.cubeKey = "";
  }

  setColors(packet) {
    if (!this.atoms || packet.header.sha256 !== this.atoms.sha256) return;
    this.atoms.colors = packet.arrays.colors;
    this.atoms.scheme = packet.header.scheme;
    this.renderer.setColors(this.atoms.colors, this.atoms.count);
  }

  setScene(scene) {
    this.scene = scene;
  }

  setPose(pose) {
    this.pose = pose;
  }

  start() {
    if (!this.ok) return;
    const tick = (now) => {
      this.source.beforeFrame?.(now);
      if (this._ready()) {
        this._draw(now);
        this.source.drawn?.(this.drawnSeq);
      }
      this._text(now);
      requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  }

  _ready() {
    return this.look && this.atoms && this.atoms.colors && this.scene && this.pose;
  }

  _fitCanvas() {
    const ratio = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(this.canvas.clientWidth * ratio));
    const h = Math.max(1, Math.round(this.canvas.clientHeight * ratio));
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.canvas.width = w;
      this.canvas.height = h;
    }
    return [w, h];
  }

  // What this frame draws, from the scene and the pose.
  frameInput() {
    const [w, h] = this._fitCanvas();
    const scene = this.scene;
    const pose = this.pose;
    const atoms = this.atoms;
    const axes = scene.view && scene.view.rotation ? rowsToMatrix(scene.view.rotation) : IDENTITY3;
    const hasCube = scene.nav_cube.enabled && pose.cube[3] > 0;
    // Without a cube the view frames the whole structure and draws every atom whole.
    const cube = hasCube
      ? { center: pose.cube.slice(0, 3), half: pose.cube[3] }
      : { center: atoms.bounds.center, half: atoms.bounds.radius / this.look.view.frame_radius };
    const probe = { center: pose.proxy, radius: scene.probe_radius_A };
    const key = hasCube ? `${cube.center} ${cube.half} ${axes}` : "whole";
    if (key !== this.cubeKey) {
      if (hasCube) atoms.inCube(cube, axes, this.list);
      else this._whole();
      this.cubeKey = key;
      this.viewKey = "";
    }
    const reach = Math.max(length(sub(cube.center, atoms.bounds.center)) + cube.half * Math.sqrt(3),
      length(sub(probe.center, atoms.bounds.center)) + probe.radius, atoms.bounds.radius);
    const camera = this.camera.frame(cube, axes, w / h,
      { center: atoms.bounds.center, radius: reach });
    const planes = hasCube ? cubePlanes(cube, axes) : cubePlanes(cube, axes).map(() => [0, 0, 0, 1]);
    for (const p of scene.clip_planes || []) {
      const n = Math.hypot(p[0], p[1], p[2]);
      planes.push(p.map((v) => v / n));
    }
    const viewKey = `${key} ${camera.eye} ${camera.back} ${camera.up} ${w} ${h} ${planes.length}`;
    if (viewKey !== this.viewKey) {
      const shown = planes.length > 6 ? this.list
        : this.occlusion.visible(this.list, camera, [w, h], cube, axes, !hasCube, this.shown);
      this.renderer.setCubeSpheres(shown);
      this.viewKey = viewKey;
    }
    // the key light follows the camera: its direction is in the view's frame
    const lights = scene.lights;
    const lightDir = normalize(camera.toWorld(normalize(lights.directional.direction)));
    const limits = (scene.device && scene.device.limits) || {};
    return {
      size: [w, h], camera, cube, axes, hasCube, planes, probe,
      touched: pose.touched, lightDir, probeLight: lights.probe.enabled,
      look: { ...this.look.colors, lit: this.look.lit },
      view: this.look.view,
      trace: hasCube,
      wire: hasCube ? this._wire(cube, axes) : null,
      arrow: this._arrow(pose, axes, probe, camera, limits),
      rect: this._rect(camera, cube, probe, hasCube, w, h),
      seq: pose.seq,
    };
  }

  _whole() {
    const atoms = this.atoms;
    const list = this.list;
    while (list.capacity < atoms.count) list.grow();
    for (let i = 0; i < atoms.count; i++) {
      list.spheres.set(atoms.positions.subarray(3 * i, 3 * i + 3), 4 * i);
      list.spheres[4 * i + 3] = atoms.radii[i];
      list.ids[2 * i] = i;
      list.ids[2 * i + 1] = 0;
    }
    list.count = atoms.count;
  }

  _wire(cube, axes) {
    const color = this.look.colors.cube_wire;
    const corner = (sx, sy, sz) => add(cube.center, scale(add(add(
      scale(column(axes, 0), sx), scale(column(axes, 1), sy)), scale(column(axes, 2), sz)),
    cube.half));
    const edges = [];
    for (const a of [-1, 1])
      for (const b of [-1, 1]) {
        edges.push([corner(-1, a, b), corner(1, a, b), color]);
        edges.push([corner(a, -1, b), corner(a, 1, b), color]);
        edges.push([corner(a, b, -1), corner(a, b, 1), color]);
      }
    return edges;
  }

  // The force on the hand as an arrow from the probe's surface (protocol/view.py's scale; its
  // colour by the device's continuous rating).
  _arrow(pose, axes, probe, camera, limits) {
    const force = apply3(axes, pose.force);
    const magnitude = length(force);
    const continuous = limits.continuous_force_n;
    const peak = limits.max_force_n ?? continuous;
    if (!(magnitude > 1e-6) || !(continuous > 0)) return null;
    const dir = scale(force, 1 / magnitude);
    const start = add(probe.center, scale(dir, probe.radius));
    const end = add(start, scale(dir,
      this.look.view.arrow_radii * probe.radius * Math.min(magnitude, peak) / continuous));
    const colors = this.look.colors.force;
    const color = magnitude <= 0.5 * continuous ? colors[0]
      : magnitude <= continuous ? colors[1] : colors[2];
    const head = 0.3 * length(sub(end, start));
    let side = cross(dir, sub(camera.eye, end));
    side = length(side) > 0 ? scale(normalize(side), head * 0.5) : [0, 0, 0];
    const back = sub(end, scale(dir, head));
    return [[start, end, color], [end, add(back, side), color], [end, sub(back, side), color]];
  }

  // The pixels the spheres can cover: the cube's projection and the probe's ([x, y, w, h]).
  _rect(camera, cube, probe, hasCube, w, h) {
    if (!hasCube) return [0, 0, w, h];
    const points = [];
    for (const sx of [-1, 1])
      for (const sy of [-1, 1])
        for (const sz of [-1, 1]) {
          const r = Math.sqrt(3) * cube.half;
          points.push(add(cube.center, [sx * r, sy * r, sz * r]));
          points.push(add(probe.center, scale([sx, sy, sz], probe.radius * Math.sqrt(3))));
        }
    let lo = [Infinity, Infinity];
    let hi = [-Infinity, -Infinity];
    for (const p of points) {
      const c = project(camera.viewproj, p);
      if (c[3] <= camera.near) return [0, 0, w, h];
      const x = c[0] / c[3];
      const y = c[1] / c[3];
      lo = [Math.min(lo[0], x), Math.min(lo[1], y)];
      hi = [Math.max(hi[0], x), Math.max(hi[1], y)];
    }
    const x0 = Math.max(0, Math.floor((lo[0] + 1) * 0.5 * w) - 1);
    const y0 = Math.max(0, Math.floor((lo[1] + 1) * 0.5 * h) - 1);
    const x1 = Math.min(w, Math.ceil((hi[0] + 1) * 0.5 * w) + 1);
    const y1 = Math.min(h, Math.ceil((hi[1] + 1) * 0.5 * h) + 1);
    return x1 > x0 && y1 > y0 ? [x0, y0, x1 - x0, y1 - y0] : null;
  }

  _draw(now) {
    const f = this.frameInput();
    const start = performance.now();
    this.renderer.draw(f);
    if (this.drawTimes) {
      this.renderer.finish(); // the frame's own cost, the browser's frame pacing aside
      this.drawTimes.push(performance.now() - start);
      if (this.drawTimes.length > DRAW_TIMES) this.drawTimes.shift();
    }
    this.lastFrame = f;
    this.frames++;
    this.drawnSeq = f.seq;
    const times = this.frameTimes;
    times.push(now);
    while (times.length > 2 && now - times[0] > FPS_WINDOW_MS) times.shift();
  }

  // From now on each frame is finished (a pixel read back) as it is drawn, and timed: what a
  // frame costs the page, apart from when the browser lets it draw and shows it.
  timeDraws() {
    if (this.ok && !this.drawTimes) this.drawTimes = [];
  }

  get drawMs() {
    const t = this.drawTimes;
    if (!t || t.length === 0) return null;
    const sorted = [...t].sort((a, b) => a - b);
    const at = (q) => sorted[Math.min(sorted.length - 1, Math.floor(q * sorted.length))];
    return [at(0.5), at(0.95)];
  }

  get fps() {
    const t = this.frameTimes;
    return t.length >= 2 ? (1000 * (t.length - 1)) / (t[t.length - 1] - t[0]) : null;
  }

  _text(now) {
    if (!this.ok) return;
    const pose = this.pose;
    const f = this.lastFrame;
    const marks = [];
    if (f && this.scene && this.scene.marks) {
      for (const m of this.scene.marks) {
        const c = project(f.camera.viewproj, m.position_A);
        if (c[3] <= f.camera.near) continue;
        const x = ((c[0] / c[3] + 1) / 2) * this.canvas.clientWidth;
        const y = ((1 - c[1] / c[3]) / 2) * this.canvas.clientHeight;
        marks.push({ id: m.id, label: m.label, x, y });
      }
    }
    const flags = pose ? pose.flags : 0;
    const force = pose && f ? Math.round(100 * length(apply3(f.axes, pose.force))) / 100 : null;
    this.overlay.update({
      status: this.source.status(this),
      touched: pose && pose.touched >= 0 ? pose.label || `atom ${pose.touched}` : null,
      contact: !!(flags & FLAG_CONTACT),
      clutched: !!(flags & FLAG_CLUTCHED),
      drifting: !!(flags & FLAG_DRIFTING),
      force,
      marks,
      markColor: this.look && this.look.colors.mark,
    }, now);
  }

  _input() {
    let drag = null;
    const ndc = (e) => {
      const r = this.canvas.getBoundingClientRect();
      return [((e.clientX - r.left) / r.width) * 2 - 1, 1 - ((e.clientY - r.top) / r.height) * 2];
    };
    this.canvas.addEventListener("pointerdown", (e) => {
      drag = ndc(e);
      this.canvas.setPointerCapture(e.pointerId);
    });
    this.canvas.addEventListener("pointermove", (e) => {
      if (!drag || !this.camera || !this.lastFrame) return;
      const p = ndc(e);
      const cam = this.lastFrame.camera;
      this.camera.orbit(cam, p[0] - drag[0], p[1] - drag[1]);
      drag = p;
    });
    this.canvas.addEventListener("pointerup", () => {
      drag = null;
    });
    this.canvas.addEventListener("wheel", (e) => {
      e.preventDefault();
      if (this.camera) this.camera.zoomBy(Math.exp(e.deltaY * 0.001));
    }, { passive: false });
    window.addEventListener("keydown", (e) => {
      if ((e.key === "r" || e.key === "R") && this.camera) this.camera.reset();
    });
  }

  // The test hooks' common part (docs/web.md).
  state() {
    return {
      seq: this.drawnSeq,
      frames: this.frames,
      structure: this.atoms ? this.atoms.name : null,
      atoms: this.atoms ? this.atoms.count : 0,
      scheme: this.atoms ? this.atoms.scheme : null,
      cube_atoms: this.list.count,
      drawn_atoms: this.renderer ? this.renderer.cubeCount : 0,
      fps: this.fps,
      draw_ms: this.drawMs,
      width: this.canvas.width,
      height: this.canvas.height,
    };
  }

  // The atom id per pixel of the last frame and what that frame was drawn from.
  pick() {
    const f = this.lastFrame;
    if (!f) return null;
    const ids = this.renderer.pickIds();
    const bytes = new Uint8Array(ids.buffer);
    let text = "";
    for (let i = 0; i < bytes.length; i += 0x8000)
      text += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
    const c = f.camera;
    return {
      seq: f.seq,
      width: this.renderer.size[0],
      height: this.renderer.size[1],
      ids: btoa(text),
      camera: {
        eye: c.eye, target: c.target, up: c.up, fov_deg: c.fovDeg, aspect: c.aspect,
        near: c.near, far: c.far,
      },
      cube: f.hasCube ? { center: f.cube.center, half: f.cube.half, axes: f.axes } : null,
      probe: f.probe,
      clip_planes: f.planes.slice(6),
    };
  }
}
