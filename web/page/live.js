// The live page: follows `sasprobe web`'s WebSocket (the page's own server, with the token in
// the page's path), draws the newest pose it was sent and tells the bridge which one it drew,
// which is also how it asks for the next: poses come at the rate the page draws. The page
// sends nothing else; the bridge passes nothing from a page to the daemon.
import { readPacket } from "sasprobe/packets.js";
import { Viewer } from "sasprobe/viewer.js";

const RECONNECT_MS = 1000;

class LiveSource {
  constructor(root) {
    this.viewer = new Viewer(root, this);
    this.socket = null;
    this.open = false;
    this.acked = null;
    this.daemon = { connected: false, endpoint: "" };
    this.stats = {};
  }

  connect() {
    const url = new URL("ws", location.href);
    url.protocol = location.protocol === "https:" ? "wss:" : "ws:";
    url.search = "";
    url.hash = "";
    const socket = new WebSocket(url);
    socket.binaryType = "arraybuffer";
    socket.onopen = () => {
      this.open = true;
      this.acked = null;
    };
    socket.onmessage = (event) => this.message(event.data);
    socket.onclose = () => {
      this.open = false;
      setTimeout(() => this.connect(), RECONNECT_MS);
    };
    this.socket = socket;
  }

  message(data) {
    const v = this.viewer;
    if (typeof data !== "string") {
      const packet = readPacket(data);
      if (packet.header.kind === "structure") v.setStructure(packet);
      else if (packet.header.kind === "colors") v.setColors(packet);
      return;
    }
    const m = JSON.parse(data);
    if (m.type === "hello") v.setLook(m);
    else if (m.type === "scene") v.setScene(m.scene);
    else if (m.type === "pose") {
      v.setPose(m);
      this.stats = m.stats || {};
    } else if (m.type === "daemon") this.daemon = m;
  }

  drawn(seq) {
    if (seq === this.acked || !this.open) return;
    this.acked = seq;
    this.socket.send(JSON.stringify({ drawn: seq }));
  }

  status(viewer) {
    if (!this.open) return "connecting to the page's server ...";
    if (!this.daemon.connected) return `waiting for the daemon at ${this.daemon.endpoint}`;
    if (!viewer.atoms) return "fetching the structure ...";
    const parts = [`${viewer.atoms.name}`, `${viewer.atoms.count.toLocaleString("en")} atoms`];
    const s = this.stats;
    if (s.rate_hz) parts.push(`haptic ${Math.round(s.rate_hz)} Hz`);
    if (s.latency_ms) parts.push(`latency ${s.latency_ms[0].toFixed(0)} ms (p95 ${s.latency_ms[1].toFixed(0)})`);
    if (viewer.fps) parts.push(`${viewer.fps.toFixed(0)} frames/s`);
    return parts.join(" · ");
  }

  state() {
    return {
      ...this.viewer.state(),
      connected: this.open && this.daemon.connected,
      rate_hz: this.stats.rate_hz ?? null,
      latency_ms: this.stats.latency_ms ?? null,
    };
  }
}

const source = new LiveSource(document.getElementById("view"));
window.sasprobe = {
  state: () => source.state(),
  pick: () => source.viewer.pick(),
  timeDraws: () => source.viewer.timeDraws(),
};
if (source.viewer.ok) {
  source.connect();
  source.viewer.start();
}
