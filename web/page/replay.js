// The replay page: a recorded session inlined in the file (web/export.py), played offline:
// play, pause, speed, and a timeline to seek with the marks on it. Frame k of the recording
// is its moment k / fps from the first pose; at time t the page shows the latest frame at or
// before t.
import { readPacket } from "sasprobe/packets.js";
import { Viewer } from "sasprobe/viewer.js";

const SPEEDS = [0.25, 0.5, 1, 2, 4];

// The bytes of a gzip-compressed, base64-encoded blob of the file (web/export.py).
async function inflate(text) {
  const bytes = Uint8Array.from(atob(text), (c) => c.charCodeAt(0));
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("gzip"));
  return new Response(stream).arrayBuffer();
}

const unpack = async (text) => readPacket(await inflate(text));

function element(parent, tag, props = {}) {
  const e = Object.assign(document.createElement(tag), props);
  parent.appendChild(e);
  return e;
}

class ReplaySource {
  constructor(root, session) {
    this.root = root;
    this.session = session;
    this.viewer = new Viewer(root, this);
    this.time = 0;
    this.playing = false;
    this.speed = 1;
    this.last = null;
    this.row = -1;
    this.structure = -1;
    this.colors = -1;
  }

  async load() {
    const s = this.session;
    const [poses, structures, colors, scenes] = await Promise.all([
      unpack(s.poses),
      Promise.all(s.structures.map((x) => unpack(x.packet))),
      Promise.all(s.colors.map(unpack)),
      inflate(s.scenes),
    ]);
    this.structures = structures;
    this.colorPackets = colors;
    this.scenes = JSON.parse(new TextDecoder().decode(scenes));
    this.rows = poses.arrays.t_s.length;
    this.duration = this.rows ? poses.arrays.t_s[this.rows - 1] : 0;
    this.poses = poses.arrays; // last: from here on the page shows the recording
    this.viewer.setLook(s.hello);
    this._controls();
    this.seek(this.time);
  }

  _controls() {
    const bar = element(this.root, "div", { className: "player" });
    this.button = element(bar, "button", { textContent: "play" });
    this.button.addEventListener("click", () => (this.playing ? this.pause() : this.play()));
    const speed = element(bar, "select", { title: "speed" });
    for (const v of SPEEDS) element(speed, "option", { value: v, textContent: `${v}×`, selected: v === 1 });
    speed.addEventListener("change", () => (this.speed = Number(speed.value)));
    const line = element(bar, "div", { className: "timeline" });
    this.slider = element(line, "input", { type: "range", min: 0, max: this.duration, step: "any", value: 0 });
    this.slider.addEventListener("input", () => this.seek(Number(this.slider.value)));
    const color = this.session.hello.colors.mark.map((c) => Math.round(c * 255)).join(",");
    for (const m of this.session.marks) {
      const tick = element(line, "span", { className: "tick", textContent: String(m.id), title: m.label });
      tick.style.left = `${(100 * m.t_s) / Math.max(this.duration, 1e-9)}%`;
      tick.style.background = `rgb(${color})`;
    }
    this.clock = element(bar, "span", { className: "time" });
    if (this.session.findings.length) {
      const box = element(this.root, "details", { className: "findings" });
      element(box, "summary", { textContent: "findings" });
      element(box, "div", { textContent: this.session.findings.join("\n") });
    }
    window.addEventListener("keydown", (e) => {
      if (e.key === " ") {
        e.preventDefault();
        this.playing ? this.pause() : this.play();
      }
    });
  }

  // The row shown at time t: the latest frame at or before t.
  rowAt(t) {
    const times = this.poses.t_s;
    let lo = 0;
    let hi = this.rows - 1;
    while (lo < hi) {
      const mid = (lo + hi + 1) >> 1;
      if (times[mid] <= t + 1e-9) lo = mid;
      else hi = mid - 1;
    }
    return lo;
  }

  show(t) {
    this.time = Math.min(Math.max(t, 0), this.duration);
    const k = this.rowAt(this.time);
    if (k === this.row) return;
    this.row = k;
    const p = this.poses;
    const v = this.viewer;
    if (p.structure[k] !== this.structure) {
      this.structure = p.structure[k];
      v.setStructure(this.structures[this.structure]);
      this.colors = -1;
    }
    const scene = this.scenes[p.scene[k]];
    if (scene.colors !== this.colors) {
      this.colors = scene.colors;
      v.setColors(this.colorPackets[this.colors]);
    }
    v.setScene(scene.scene);
    const labels = this.session.labels[this.structure];
    const slice = (a, n) => Array.from(a.subarray(n * k, n * k + n));
    v.setPose({
      seq: p.seq[k], proxy: slice(p.proxy, 3), goal: slice(p.goal, 3), force: slice(p.force, 3),
      cube: slice(p.cube, 4), touched: p.touched[k], flags: p.flags[k],
      label: labels[String(p.touched[k])] || null,
    });
  }

  seek(t) {
    if (!this.poses) {  // still loading: shown once loaded
      this.time = t;
      return;
    }
    this.show(t);
    this.slider.value = this.time;
  }

  play() {
    if (!this.poses) return;
    if (this.time >= this.duration) this.seek(0);
    this.playing = true;
    this.last = null;
    this.button.textContent = "pause";
  }

  pause() {
    this.playing = false;
    if (this.button) this.button.textContent = "play";
  }

  beforeFrame(now) {
    if (this.playing) {
      if (this.last !== null) this.seek(this.time + ((now - this.last) / 1000) * this.speed);
      this.last = now;
      if (this.time >= this.duration) this.pause();
    }
    if (this.clock) this.clock.textContent = `${this.time.toFixed(2)} / ${this.duration.toFixed(2)} s`;
  }

  status(viewer) {
    if (!viewer.atoms) return "loading the recording ...";
    const parts = [this.session.recording, viewer.atoms.name,
      `${viewer.atoms.count.toLocaleString("en")} atoms`, `${this.speed}×`];
    if (viewer.fps) parts.push(`${viewer.fps.toFixed(0)} frames/s`);
    return parts.join(" · ");
  }

  state() {
    return {
      ...this.viewer.state(), loaded: !!this.poses, time_s: this.time, playing: this.playing,
      duration_s: this.duration ?? null,
    };
  }
}

const session = JSON.parse(document.getElementById("sasprobe-session").textContent);
const source = new ReplaySource(document.getElementById("view"), session);
window.sasprobe = {
  state: () => source.state(),
  pick: () => source.viewer.pick(),
  timeDraws: () => source.viewer.timeDraws(),
  seek: (seconds) => source.seek(seconds),
  play: () => source.play(),
  pause: () => source.pause(),
};
if (source.viewer.ok) source.load().then(() => source.viewer.start());
