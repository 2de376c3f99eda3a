// WebGL2: the structure uploaded once (atom tables, the trace), the cube's atoms whenever the
// cube moves, and per frame only uniforms and a few lines (shaders.js says what each step
// draws).
import {
  FULLSCREEN_VERTEX, LINE_FRAGMENT, LINE_VERTEX, MAX_PLANES, SEGMENT_VERTICES, SHADE_FRAGMENT,
  SPHERE_FRAGMENT, SPHERE_VERTEX, SPHERE_VERTICES, TABLE_WIDTH,
} from "sasprobe/shaders.js";

const ARROW_PX = 2.5; // the force arrow: wider than the cube's edges

// Each of `count` records of `width` elements, `times` over in a row: data for each vertex of
// a shape drawn as plain triangles (shaders.js says why not instanced).
function repeatEach(array, width, count, times) {
  const out = new array.constructor(width * count * times);
  for (let i = 0; i < count; i++) {
    const record = array.subarray(width * i, width * (i + 1));
    for (let v = 0; v < times; v++) out.set(record, width * (times * i + v));
  }
  return out;
}

function compile(gl, type, source) {
  const shader = gl.createShader(type);
  gl.shaderSource(shader, source);
  gl.compileShader(shader);
  if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS))
    throw new Error(`shader: ${gl.getShaderInfoLog(shader)}`);
  return shader;
}

function program(gl, vertex, fragment) {
  const p = gl.createProgram();
  gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, vertex));
  gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, fragment));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS))
    throw new Error(`program: ${gl.getProgramInfoLog(p)}`);
  const uniforms = {};
  const n = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS);
  for (let i = 0; i < n; i++) {
    const name = gl.getActiveUniform(p, i).name.replace(/\[0\]$/, "");
    uniforms[name] = gl.getUniformLocation(p, name);
  }
  return { program: p, uniforms };
}

// The bounding rectangle of two [x, y, w, h] (null: nothing), the whole picture before a
// first frame.
function union(a, b, w, h) {
  if (a === undefined) return [0, 0, w, h];
  if (!a || !b) return a || b || [0, 0, 0, 0];
  const x = Math.min(a[0], b[0]);
  const y = Math.min(a[1], b[1]);
  return [x, y, Math.max(a[0] + a[2], b[0] + b[2]) - x, Math.max(a[1] + a[3], b[1] + b[3]) - y];
}

export class Renderer {
  constructor(canvas) {
    const gl = canvas.getContext("webgl2", { antialias: false, depth: true, alpha: false });
    if (!gl) throw new Error("no WebGL2");
    this.gl = gl;
    this.canvas = canvas;
    this.pixel = new Uint8Array(4);
    this.spheres = program(gl, SPHERE_VERTEX, SPHERE_FRAGMENT);
    this.shade = program(gl, FULLSCREEN_VERTEX, SHADE_FRAGMENT);
    this.lines = program(gl, LINE_VERTEX, LINE_FRAGMENT);
    this.emptyVao = gl.createVertexArray();
    this.cubeSpheres = this._sphereVao();
    this.probeSphere = this._sphereVao();
    this.trace = this._lineVao();
    this.wire = this._lineVao();
    this.arrow = this._lineVao();
    this.atomTable = gl.createTexture();
    this.colorTable = gl.createTexture();
    this.size = [0, 0];
    this.targets = null;
    this.cubeCount = 0;
    this.traceCount = 0;
    this.frames = 0;
  }

  _sphereVao() {
    const gl = this.gl;
    const vao = gl.createVertexArray();
    const buffer = gl.createBuffer();
    const ids = gl.createBuffer();
    gl.bindVertexArray(vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 4, gl.FLOAT, false, 16, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, ids);
    gl.enableVertexAttribArray(1);
    gl.vertexAttribIPointer(1, 2, gl.INT, 8, 0);
    gl.bindVertexArray(null);
    return { vao, buffer, ids, capacity: 0 };
  }

  _lineVao() {
    const gl = this.gl;
    const vao = gl.createVertexArray();
    const buffer = gl.createBuffer();
    gl.bindVertexArray(vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    // per vertex of a segment: from xyz, to xyz (float), colour rgb (bytes, normalised) + 1 pad
    for (const [loc, size, type, offset] of [[0, 3, gl.FLOAT, 0], [1, 3, gl.FLOAT, 12],
      [2, 3, gl.UNSIGNED_BYTE, 24]]) {
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, size, type, type === gl.UNSIGNED_BYTE, 28, offset);
    }
    gl.bindVertexArray(null);
    return { vao, buffer, count: 0 };
  }

  // The structure, once: the atom tables the shading reads and the trace's segments.
  setStructure(atoms) {
    const gl = this.gl;
    const rows = Math.max(1, Math.ceil(atoms.count / TABLE_WIDTH));
    const spheres = new Float32Array(rows * TABLE_WIDTH * 4);
    for (let i = 0; i < atoms.count; i++) {
      spheres[4 * i] = atoms.positions[3 * i];
      spheres[4 * i + 1] = atoms.positions[3 * i + 1];
      spheres[4 * i + 2] = atoms.positions[3 * i + 2];
      spheres[4 * i + 3] = atoms.radii[i];
    }
    this._table(this.atomTable, gl.RGBA32F, gl.FLOAT, rows, spheres);
    this.tableRows = rows;
    const pairs = atoms.trace;
    const n = pairs.length / 2;
    const data = new ArrayBuffer(28 * n);
    const f = new Float32Array(data);
    const b = new Uint8Array(data);
    const p = atoms.positions;
    for (let s = 0; s < n; s++) {
      const i = pairs[2 * s];
      const j = pairs[2 * s + 1];
      f.set([p[3 * i], p[3 * i + 1], p[3 * i + 2], p[3 * j], p[3 * j + 1], p[3 * j + 2]], 7 * s);
      b.set(atoms.traceColors.subarray(3 * s, 3 * s + 3), 28 * s + 24);
    }
    this._upload(this.trace, data, n);
    this.cubeCount = 0;
  }

  setColors(colors, count) {
    const gl = this.gl;
    const data = new Uint8Array(this.tableRows * TABLE_WIDTH * 4);
    for (let i = 0; i < count; i++) {
      data[4 * i] = colors[3 * i];
      data[4 * i + 1] = colors[3 * i + 1];
      data[4 * i + 2] = colors[3 * i + 2];
      data[4 * i + 3] = 255;
    }
    this._table(this.colorTable, gl.RGBA8, gl.UNSIGNED_BYTE, this.tableRows, data);
  }

  _table(texture, format, type, rows, data) {
    const gl = this.gl;
    gl.bindTexture(gl.TEXTURE_2D, texture);
    gl.texImage2D(gl.TEXTURE_2D, 0, format, TABLE_WIDTH, rows, 0, gl.RGBA, type, data);
    for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER])
      gl.texParameteri(gl.TEXTURE_2D, p, gl.NEAREST);
  }

  // `count` segments of 28 bytes each (see _lineVao).
  _upload(lines, data, count) {
    const gl = this.gl;
    gl.bindBuffer(gl.ARRAY_BUFFER, lines.buffer);
    const words = new Uint32Array(data); // 7 words a segment
    gl.bufferData(gl.ARRAY_BUFFER, repeatEach(words, 7, count, SEGMENT_VERTICES), gl.DYNAMIC_DRAW);
    lines.count = count;
  }

  // The cube's atoms (a SphereList), whenever the cube moves.
  setCubeSpheres(list) {
    this._spheres(this.cubeSpheres, list.spheres, list.ids, list.count);
    this.cubeCount = list.count;
  }

  _spheres(target, spheres, ids, count) {
    const gl = this.gl;
    const n = SPHERE_VERTICES;
    gl.bindBuffer(gl.ARRAY_BUFFER, target.buffer);
    if (count > target.capacity) {
      target.capacity = Math.max(count, 2 * target.capacity);
      gl.bufferData(gl.ARRAY_BUFFER, 16 * n * target.capacity, gl.DYNAMIC_DRAW);
      gl.bindBuffer(gl.ARRAY_BUFFER, target.ids);
      gl.bufferData(gl.ARRAY_BUFFER, 8 * n * target.capacity, gl.DYNAMIC_DRAW);
      gl.bindBuffer(gl.ARRAY_BUFFER, target.buffer);
    }
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, repeatEach(spheres, 4, count, n));
    gl.bindBuffer(gl.ARRAY_BUFFER, target.ids);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, repeatEach(ids, 2, count, n));
  }

  // Line segments [[from, to, rgb 0..1], ...] into one of the line lists.
  _segments(lines, segments) {
    const data = new ArrayBuffer(28 * segments.length);
    const f = new Float32Array(data);
    const b = new Uint8Array(data);
    segments.forEach(([from, to, color], s) => {
      f.set([...from, ...to], 7 * s);
      b.set(color.map((c) => Math.round(c * 255)), 28 * s + 24);
    });
    this._upload(lines, data, segments.length);
  }

  _resize() {
    const gl = this.gl;
    const w = this.canvas.width;
    const h = this.canvas.height;
    if (this.targets && w === this.size[0] && h === this.size[1]) return;
    if (this.targets) {
      gl.deleteFramebuffer(this.targets.fbo);
      gl.deleteTexture(this.targets.ids);
      gl.deleteTexture(this.targets.depth);
    }
    const ids = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, ids);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RG32I, w, h);
    const depth = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, depth);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.DEPTH_COMPONENT32F, w, h);
    for (const t of [ids, depth]) {
      gl.bindTexture(gl.TEXTURE_2D, t);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    }
    const fbo = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, ids, 0);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.TEXTURE_2D, depth, 0);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    this.targets = { fbo, ids, depth };
    this.size = [w, h];
    this.drawnRect = undefined; // new targets: cleared whole
  }

  // One frame. `f`: {camera, cube, axes (row-major), planes (cube faces then clip planes),
  // probe {center, radius} or null, touched, lightDir (world), probeLight, look (colours and
  // Phong terms), view (protocol/view.py's conventions), wire, arrow (segments or null),
  // rect ([x, y, w, h] where spheres can be, or null)}.
  draw(f) {
    const gl = this.gl;
    this._resize();
    const [w, h] = this.size;
    const cam = f.camera;
    const planes = new Float32Array(4 * MAX_PLANES);
    f.planes.slice(0, MAX_PLANES).forEach((p, i) => planes.set(p, 4 * i));
    const t = Math.tan((cam.fovDeg * Math.PI) / 360);
    const forward = cam.back.map((v) => -v);
    const rightT = cam.right.map((v) => v * t * cam.aspect);
    const upT = cam.up.map((v) => v * t);
    const rect = f.rect;

    // 1. ids and depth of the spheres
    // Only `rect` is drawn, and the last frame's and this one's cleared: outside them the
    // ids are already clear, so a pick reads the whole picture right.
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.targets.fbo);
    gl.viewport(0, 0, w, h);
    gl.enable(gl.SCISSOR_TEST);
    gl.scissor(...union(this.drawnRect, rect, w, h));
    gl.depthMask(true);
    gl.clearBufferiv(gl.COLOR, 0, new Int32Array([-1, -1, 0, 0]));
    gl.clearBufferfv(gl.DEPTH, 0, new Float32Array([1]));
    gl.disable(gl.SCISSOR_TEST);
    this.drawnRect = rect;
    if (rect) {
      gl.enable(gl.SCISSOR_TEST);
      gl.scissor(...rect);
      gl.enable(gl.DEPTH_TEST);
      gl.depthFunc(gl.LESS);
      gl.depthMask(true);
      const s = this.spheres;
      gl.useProgram(s.program);
      gl.uniformMatrix4fv(s.uniforms.u_viewproj, false, cam.viewproj);
      gl.uniform3fv(s.uniforms.u_eye, cam.eye);
      gl.uniform4fv(s.uniforms.u_planes, planes);
      gl.uniform1i(s.uniforms.u_n_planes, f.planes.length);
      if (this.cubeCount > 0) {
        gl.bindVertexArray(this.cubeSpheres.vao);
        gl.drawArrays(gl.TRIANGLES, 0, SPHERE_VERTICES * this.cubeCount);
      }
      if (f.probe) {
        const p = f.probe;
        this._spheres(this.probeSphere, new Float32Array([...p.center, p.radius]),
          new Int32Array([-2, -1]), 1);
        gl.bindVertexArray(this.probeSphere.vao);
        gl.drawArrays(gl.TRIANGLES, 0, SPHERE_VERTICES);
      }
      gl.disable(gl.SCISSOR_TEST);
    }

    // 2. the lit surfaces into the picture (the rest is the background)
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, w, h);
    const bg = f.look.background;
    gl.clearColor(bg[0], bg[1], bg[2], 1);
    gl.depthMask(true);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (rect) {
      gl.enable(gl.SCISSOR_TEST);
      gl.scissor(...rect);
      gl.enable(gl.DEPTH_TEST);
      gl.depthFunc(gl.ALWAYS);
      const s = this.shade;
      const u = s.uniforms;
      const lit = f.look.lit;
      gl.useProgram(s.program);
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, this.targets.ids);
      gl.activeTexture(gl.TEXTURE1);
      gl.bindTexture(gl.TEXTURE_2D, this.targets.depth);
      gl.activeTexture(gl.TEXTURE2);
      gl.bindTexture(gl.TEXTURE_2D, this.atomTable);
      gl.activeTexture(gl.TEXTURE3);
      gl.bindTexture(gl.TEXTURE_2D, this.colorTable);
      gl.uniform1i(u.u_ids, 0);
      gl.uniform1i(u.u_depth, 1);
      gl.uniform1i(u.u_atoms, 2);
      gl.uniform1i(u.u_colors, 3);
      gl.uniform2f(u.u_size, w, h);
      gl.uniform3fv(u.u_eye, cam.eye);
      gl.uniform3fv(u.u_forward, forward);
      gl.uniform3fv(u.u_right_t, rightT);
      gl.uniform3fv(u.u_up_t, upT);
      gl.uniform4fv(u.u_planes, planes);
      const probe = f.probe || { center: [0, 0, 0], radius: 0 };
      gl.uniform4f(u.u_probe, ...probe.center, probe.radius);
      gl.uniform1i(u.u_touched, f.touched);
      gl.uniform3fv(u.u_background, bg);
      gl.uniform3fv(u.u_highlight, f.look.highlight);
      gl.uniform3fv(u.u_probe_color, f.look.probe);
      gl.uniform3fv(u.u_light_dir, f.lightDir);
      gl.uniform1i(u.u_probe_light, f.probeLight && f.probe ? 1 : 0);
      gl.uniform1f(u.u_ambient, lit.ambient);
      gl.uniform1f(u.u_directional, lit.directional);
      gl.uniform1f(u.u_probe_intensity, lit.probe);
      gl.uniform3fv(u.u_probe_atten, lit.probe_attenuation);
      gl.uniform1f(u.u_probe_range, lit.probe_range);
      gl.uniform1f(u.u_shininess, lit.shininess);
      gl.uniform1f(u.u_specular, lit.specular);
      gl.bindVertexArray(this.emptyVao);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
      gl.disable(gl.SCISSOR_TEST);
    }

    // 3. lines: the trace (outside the cube's window), the cube's edges, the force arrow
    const l = this.lines;
    const u = l.uniforms;
    gl.useProgram(l.program);
    gl.uniformMatrix4fv(u.u_viewproj, false, cam.viewproj);
    gl.uniform2f(u.u_size, w, h);
    gl.uniform1f(u.u_focal, cam.proj[5]);
    gl.uniform1f(u.u_near, cam.near);
    gl.uniform3fv(u.u_eye, cam.eye);
    gl.uniform3fv(u.u_forward, forward);
    gl.uniform3fv(u.u_right_t, rightT);
    gl.uniform3fv(u.u_up_t, upT);
    gl.uniform4f(u.u_cube, ...f.cube.center, f.cube.half);
    const a = f.axes; // row-major: the uniform wants columns, i.e. the transpose's rows
    gl.uniformMatrix3fv(u.u_cube_axes, false, [a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8]]);
    gl.uniform4fv(u.u_planes, planes);
    gl.uniform1i(u.u_n_planes, f.planes.length);
    gl.uniform3fv(u.u_light_dir, f.lightDir);
    gl.uniform1f(u.u_ambient, f.look.lit.ambient);
    gl.uniform1f(u.u_directional, f.look.lit.directional);
    gl.enable(gl.DEPTH_TEST);
    gl.depthFunc(gl.LESS);
    if (f.trace && this.trace.count > 0) {
      gl.uniform1i(u.u_window, 1);
      gl.uniform1i(u.u_tube, 1);
      gl.uniform1f(u.u_width_px, f.view.trace_min_px);
      gl.uniform1f(u.u_width_A, 2 * f.view.trace_radius);
      gl.bindVertexArray(this.trace.vao);
      gl.drawArrays(gl.TRIANGLES, 0, SEGMENT_VERTICES * this.trace.count);
    }
    gl.uniform1i(u.u_window, 0);
    gl.uniform1i(u.u_tube, 0);
    gl.uniform1i(u.u_n_planes, 6); // the clip planes cut the trace only
    gl.uniform1f(u.u_width_A, 0);
    if (f.wire) {
      this._segments(this.wire, f.wire);
      gl.depthFunc(gl.LEQUAL);
      gl.depthMask(false);
      gl.uniform1f(u.u_width_px, f.view.wire_px);
      gl.bindVertexArray(this.wire.vao);
      gl.drawArrays(gl.TRIANGLES, 0, SEGMENT_VERTICES * this.wire.count);
    }
    if (f.arrow) {
      this._segments(this.arrow, f.arrow);
      gl.disable(gl.DEPTH_TEST); // what the hand feels is never hidden
      gl.uniform1f(u.u_width_px, ARROW_PX);
      gl.bindVertexArray(this.arrow.vao);
      gl.drawArrays(gl.TRIANGLES, 0, SEGMENT_VERTICES * this.arrow.count);
    }
    gl.depthMask(true);
    gl.bindVertexArray(null);
    this.frames++;
  }

  // Waits until everything drawn so far is done: a pixel read back (SwiftShader defers the
  // drawing past gl.finish until something reads it).
  finish() {
    const gl = this.gl;
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, this.pixel);
  }

  // The atom id of every pixel of the last frame (-1: no atom; -2: the probe), row 0 at the
  // top, as an Int32Array of width * height.
  pickIds() {
    const gl = this.gl;
    const [w, h] = this.size;
    const raw = new Int32Array(4 * w * h);
    gl.bindFramebuffer(gl.FRAMEBUFFER, this.targets.fbo);
    gl.readPixels(0, 0, w, h, gl.RGBA_INTEGER, gl.INT, raw);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    const ids = new Int32Array(w * h);
    for (let y = 0; y < h; y++)
      for (let x = 0; x < w; x++) ids[(h - 1 - y) * w + x] = raw[4 * (y * w + x)];
    return ids;
  }
}
