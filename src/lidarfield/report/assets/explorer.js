// lidarfield's pair explorer: one pair's stages in a 3-D view and a top view, with a stage slider.
// A small WebGL viewer of its own (no library): it draws 2 x 120,000 points in a fraction of
// the time plotly.js takes (bench/explorer.py). Opens from file:// with no network: the data
// comes in as scripts (explorer/*.js) that call lidarfieldExplorer.add(key, base64 blob); see
// lidarfield.report.explorer_data for the format.
(function () {
  "use strict";
  let blobs = {}; // the explorer whose data scripts are loading: its blobs by key
  const DTYPES = { f8: Float64Array, f4: Float32Array, i4: Int32Array, u4: Uint32Array, u1: Uint8Array };

  function decode(b64) {
    const text = atob(b64);
    const bytes = new Uint8Array(text.length);
    for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
    if (String.fromCharCode(bytes[0], bytes[1], bytes[2], bytes[3]) !== "LFX1") throw new Error("not an explorer blob");
    const length = new DataView(bytes.buffer).getUint32(4, true);
    const header = JSON.parse(new TextDecoder().decode(bytes.subarray(8, 8 + length)));
    const start = 8 + length, arrays = {};
    for (const a of header.arrays) {
      const Type = DTYPES[a.dtype], count = a.shape.reduce((p, q) => p * q, 1);
      arrays[a.name] = { data: new Type(bytes.buffer, start + a.offset, count), shape: a.shape };
    }
    return { header, arrays };
  }

  // ---- colours ----
  const rgb = hex => [1, 3, 5].map(i => parseInt(hex.slice(i, i + 2), 16) / 255);
  const CLOUD_COLOURS = ["#a8a8a8", "#7f9cc0"];
  const ORIGIN_COLOURS = ["#444444", "#466ea0"];
  // one colour per stage for the points it removed and the corrections it made (stage 1 first)
  const STAGE_COLOURS = ["#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22"];
  const TAG_COLOURS = ["#bbbbbb", "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2"];
  const NO_VALUE = "#bbbbbb";
  // matplotlib's viridis and plasma at ten even steps (the static figures' colour maps)
  const SCALES = {
    magnitude: ["#440154", "#482878", "#3e4989", "#31688e", "#26828e", "#1f9e89", "#35b779", "#6ece58", "#b5de2b", "#fde725"],
    z: ["#0d0887", "#46039f", "#7201a8", "#9c179e", "#bd3786", "#d8576b", "#ed7953", "#fb9f3a", "#fdca26", "#f0f921"],
  };
  const stageColour = level => STAGE_COLOURS[(level - 1) % STAGE_COLOURS.length];

  function scaleColour(stops, t) {
    const x = Math.min(Math.max(t, 0), 1) * (stops.length - 1), i = Math.min(Math.floor(x), stops.length - 2);
    const a = rgb(stops[i]), b = rgb(stops[i + 1]), f = x - i;
    return [0, 1, 2].map(k => a[k] + f * (b[k] - a[k]));
  }

  const LAYERS = [
    ["cloud1", "cloud 1 (kept)"],
    ["cloud2", "cloud 2 (kept)"],
    ["removed", "removed points"],
    ["corrections", "corrections"],
    ["vectors", "vectors"],
    ["origins", "sensor origins"],
  ];
  const fmt = (x, digits) => (Number.isFinite(x) ? x.toFixed(digits) : "–");
  const count = n => n.toLocaleString("en-US");
  // a round step (1, 2 or 5 times a power of ten) of at least span / n
  function niceStep(span, n) {
    const raw = span / n, power = 10 ** Math.floor(Math.log10(raw));
    return [1, 2, 5, 10].map(s => s * power).find(s => s >= raw);
  }

  // ---- 4 x 4 matrices, column-major as WebGL takes them ----
  function multiply(a, b) {
    const out = new Float32Array(16);
    for (let c = 0; c < 4; c++)
      for (let r = 0; r < 4; r++) {
        let s = 0;
        for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
        out[c * 4 + r] = s;
      }
    return out;
  }
  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
  }
  function ortho(l, r, b, t, n, f) {
    return [2 / (r - l), 0, 0, 0, 0, 2 / (t - b), 0, 0, 0, 0, -2 / (f - n), 0,
      -(r + l) / (r - l), -(t + b) / (t - b), -(f + n) / (f - n), 1];
  }
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const unit = a => { const n = Math.hypot(...a) || 1; return a.map(v => v / n); };
  function lookAt(eye, target, up) {
    const z = unit(sub(eye, target)), x = unit(cross(up, z)), y = cross(z, x);
    return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
  }
  // clip coordinates of a point: [x / w, y / w, w]
  function project(m, x, y, z) {
    const w = m[3] * x + m[7] * y + m[11] * z + m[15];
    return [(m[0] * x + m[4] * y + m[8] * z + m[12]) / w, (m[1] * x + m[5] * y + m[9] * z + m[13]) / w, w];
  }

  // ---- cameras: the 3-D view orbits a target (z up), the top view looks down z ----
  const FOV = Math.PI / 4;
  function homeCamera(view, bounds, aspect) {
    const centre = bounds.map(r => (r[0] + r[1]) / 2), span = bounds.map(r => r[1] - r[0]);
    if (view === "top") return { centre: centre.slice(0, 2), half: 0.55 * Math.max(span[1], span[0] / aspect) };
    const radius = 0.5 * Math.hypot(...span);
    return { target: centre, distance: 0.8 * radius / Math.tan(FOV / 2), azimuth: -Math.PI / 2 - 0.6, elevation: 0.6 };
  }
  function eyeOf(cam) {
    const ce = Math.cos(cam.elevation);
    return [0, 1, 2].map(k => cam.target[k] + cam.distance * [ce * Math.cos(cam.azimuth), ce * Math.sin(cam.azimuth), Math.sin(cam.elevation)][k]);
  }
  function viewMatrix(view, cam, aspect) {
    if (view === "top") {
      const h = cam.half, w = h * aspect, [x, y] = cam.centre;
      return ortho(x - w, x + w, y - h, y + h, -1e6, 1e6);
    }
    const near = cam.distance / 500, far = cam.distance * 50;
    return multiply(perspective(FOV, aspect, near, far), lookAt(eyeOf(cam), cam.target, [0, 0, 1]));
  }

  // ---- WebGL ----
  const POINTS_VS = `
    attribute vec3 position; attribute float by;
    uniform mat4 mvp; uniform vec3 kept; uniform vec3 stageColours[8];
    uniform float showKept, showRemoved, sizeKept, sizeRemoved;
    varying vec3 colour;
    void main() {
      bool removed = by > 0.5;
      colour = removed ? stageColours[int(mod(by - 1.0, 8.0) + 0.5)] : kept;
      if ((removed ? showRemoved : showKept) < 0.5) { gl_Position = vec4(2.0, 2.0, 2.0, 1.0); gl_PointSize = 1.0; return; }
      gl_Position = mvp * vec4(position, 1.0);
      gl_PointSize = removed ? sizeRemoved : sizeKept;
    }`;
  const COLOURED_VS = `
    attribute vec3 position; attribute vec3 rgb;
    uniform mat4 mvp; uniform float size;
    varying vec3 colour;
    void main() { colour = rgb; gl_Position = mvp * vec4(position, 1.0); gl_PointSize = size; }`;
  // Lines of a width in pixels: each segment two triangles, its ends pushed apart across the
  // segment's direction on the screen (WebGL draws gl.LINES one pixel wide).
  const WIDE_VS = `
    attribute vec3 position; attribute vec3 other; attribute float side; attribute vec3 rgb;
    uniform mat4 mvp; uniform vec2 halfViewport; uniform float halfWidth;
    varying vec3 colour;
    void main() {
      vec4 a = mvp * vec4(position, 1.0), b = mvp * vec4(other, 1.0);
      vec2 d = b.xy / b.w * halfViewport - a.xy / a.w * halfViewport;
      d = length(d) > 1e-6 ? normalize(d) : vec2(1.0, 0.0);
      a.xy += vec2(-d.y, d.x) * side * halfWidth / halfViewport * a.w;
      gl_Position = a;
      colour = rgb;
    }`;
  const FS = `
    precision mediump float;
    varying vec3 colour; uniform float round;
    void main() {
      if (round > 0.5) { vec2 d = gl_PointCoord - 0.5; if (dot(d, d) > 0.25) discard; }
      gl_FragColor = vec4(colour, 1.0);
    }`;

  function program(gl, vs, fs) {
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, src);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    const loc = {};
    const n = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < n; i++) { const name = gl.getActiveUniform(p, i).name.replace("[0]", ""); loc[name] = gl.getUniformLocation(p, name); }
    for (const a of ["position", "by", "rgb", "other", "side"]) loc[a] = gl.getAttribLocation(p, a);
    return { p, loc };
  }

  // One view: its canvas (WebGL), an overlay (2-D: labels, rings, scale) and a tooltip.
  function makeView(view, box) {
    const canvas = control("canvas", { className: "gl" }, box);
    const overlay = control("canvas", { className: "overlay" }, box);
    overlay.style.pointerEvents = "none";
    const tooltip = control("div", { className: "explorer-tooltip" }, box);
    tooltip.hidden = true;
    // preserveDrawingBuffer: the PNG export reads the canvas after the frame
    const gl = canvas.getContext("webgl", { preserveDrawingBuffer: true, antialias: true });
    if (!gl) return null;
    const v = { view, box, canvas, overlay, tooltip, gl, buffers: {}, camera: null, mvp: null };
    v.points = program(gl, POINTS_VS, FS);
    v.coloured = program(gl, COLOURED_VS, FS);
    v.wide = program(gl, WIDE_VS, FS);
    return v;
  }

  function upload(v, name, data) {
    const gl = v.gl;
    if (!v.buffers[name]) v.buffers[name] = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, v.buffers[name]);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    v.buffers[name].length = data.length;
  }

  function attribute(v, loc, name, size, type) {
    const gl = v.gl;
    gl.bindBuffer(gl.ARRAY_BUFFER, v.buffers[name]);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, size, type || gl.FLOAT, false, 0, 0);
  }

  function resize(v) {
    const dpr = window.devicePixelRatio || 1, r = v.box.getBoundingClientRect();
    const w = Math.max(1, Math.round(r.width * dpr)), h = Math.max(1, Math.round(r.height * dpr));
    for (const c of [v.canvas, v.overlay]) if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
    return dpr;
  }

  // ---- the data of a stage, as drawn ----

  // Which points are left (0) or which stage removed them, and where the left ones are, at
  // every stage (a stage that moves points gets its own copy). Positions at or above a cloud's
  // loaded count (the rest, not loaded) are skipped.
  function stageStates(pts, stages) {
    const states = [];
    let removedBy = [new Uint8Array(pts.n[0]), new Uint8Array(pts.n[1])];
    let xyz = [pts.xyz[0], pts.xyz[1]];
    for (const s of stages) {
      if (!s) { states.push(null); continue; }
      const before = xyz;
      removedBy = removedBy.map(a => a.slice());
      const moves = [[], []];
      for (const c of [0, 1]) {
        const removed = s.arrays[`removed${c + 1}`];
        if (removed) for (const i of removed.data) if (i < pts.n[c]) removedBy[c][i] = Math.min(s.header.level, 255);
        const moved = s.arrays[`moved${c + 1}`];
        if (moved && moved.data.length) {
          const to = s.arrays[`moved${c + 1}_xyz`].data, copy = xyz[c].slice();
          moved.data.forEach((i, k) => { if (i < pts.n[c]) { copy.set(to.subarray(3 * k, 3 * k + 3), 3 * i); moves[c].push(i); } });
          xyz = c === 0 ? [copy, xyz[1]] : [xyz[0], copy];
        }
      }
      states.push({ removedBy, xyz, before, moves });
    }
    return states;
  }

  // The positions drawn at stage k: a kept point where it is, a removed one where it was when removed.
  function drawnPositions(ctx, k, c) {
    const st = ctx.states[k];
    if (!ctx.anyMoves) return st.xyz[c];
    const out = st.xyz[c].slice(), by = st.removedBy[c];
    for (let i = 0; i < by.length; i++)
      if (by[i]) { const at = ctx.states[by[i]].before[c]; out[3 * i] = at[3 * i]; out[3 * i + 1] = at[3 * i + 1]; out[3 * i + 2] = at[3 * i + 2]; }
    return out;
  }

  function voxelText(s, i) {
    const h = s.header, a = s.arrays;
    const bins = h.bins.map((b, k) => `${b.replace("_bin", "")} ${a.bins.data[3 * i + k]}`).join(", ");
    const tags = h.tags.filter((t, bit) => (a.tags.data[i] >>> bit) & 1);
    const se = a.se ? a.se.data[i] : NaN, z = a.z ? a.z.data[i] : NaN;
    return (
      `voxel ${a.voxel.data[i]} (${bins})<br>n1 ${a.n.data[2 * i]}, n2 ${a.n.data[2 * i + 1]}` +
      `<br>|d| ${fmt(a.magnitude.data[i], 4)} m, se ${fmt(se, 4)} m, z ${fmt(z, 2)}` +
      `<br>tags: ${tags.length ? tags.join(", ") : "none"}`
    );
  }

  // The colour scale of a mode over every loaded stage: {kind, top} or {kind: "tag", names}.
  function colourScale(mode, stages) {
    const loaded = stages.filter(Boolean);
    if (mode === "tag") return { kind: "tag", names: ["no tag", ...(loaded.length ? loaded[0].header.tags : [])] };
    let top = 0;
    for (const s of loaded) {
      const values = mode === "z" ? s.arrays.z && s.arrays.z.data : s.arrays.magnitude.data;
      if (values) for (const x of values) if (Math.abs(x) > top) top = Math.abs(x);
    }
    return { kind: mode, top: top > 0 ? top : 1 };
  }

  function vectorColours(s, scale) {
    const a = s.arrays, n = a.magnitude.data.length, out = new Float32Array(3 * n);
    for (let i = 0; i < n; i++) {
      let c;
      if (scale.kind === "tag") {
        const bits = a.tags.data[i];
        const first = bits ? 31 - Math.clz32(bits & -bits) + 1 : 0; // its first tag, 1-based
        c = rgb(TAG_COLOURS[first % TAG_COLOURS.length]);
      } else {
        const x = scale.kind === "z" ? (a.z ? Math.abs(a.z.data[i]) : NaN) : a.magnitude.data[i];
        c = Number.isFinite(x) ? scaleColour(SCALES[scale.kind], x / scale.top) : rgb(NO_VALUE);
      }
      out.set(c, 3 * i);
    }
    return out;
  }

  // An arrow from a to b: its shaft and a head of two strokes, a fifth of its length, in the
  // plane of the arrow and the vertical (or x for a vertical arrow).
  function pushArrow(out, a, b) {
    out.push(...a, ...b);
    const d = sub(b, a), len = Math.hypot(...d);
    if (!(len > 0)) return;
    const side = unit(cross(d, Math.abs(d[2]) > 0.9 * len ? [1, 0, 0] : [0, 0, 1]));
    for (const sign of [1, -1]) {
      const tip = [0, 1, 2].map(k => b[k] - 0.2 * d[k] + sign * 0.08 * len * side[k]);
      out.push(...b, ...tip);
    }
  }

  // The triangles of wide segments (6 numbers a segment, a colour at each end): for each, its
  // four corners as two triangles, each vertex with its end, the other end and its side.
  function wideLines(segments, colours) {
    const n = segments.length / 6, position = new Float32Array(18 * n), other = new Float32Array(18 * n);
    const side = new Float32Array(6 * n), rgb = new Float32Array(18 * n);
    // the corners: [end, side]: A+, A-, B+ and A-, B-, B+ (at B the direction is reversed, so is the side)
    const corners = [[0, 1], [0, -1], [1, -1], [0, -1], [1, 1], [1, -1]];
    for (let i = 0; i < n; i++)
      corners.forEach(([end, sign], k) => {
        const v = 6 * i + k, at = 6 * i + 3 * end, to = 6 * i + 3 * (1 - end);
        for (let q = 0; q < 3; q++) {
          position[3 * v + q] = segments[at + q];
          other[3 * v + q] = segments[to + q];
          rgb[3 * v + q] = colours[at + q];
        }
        side[v] = sign;
      });
    return { position, other, side, rgb };
  }

  // Everything drawn at the current stage: the GL buffers' contents and what the tests read.
  function frame(ctx) {
    const k = ctx.stage, s = ctx.stages[k], st = ctx.states[k], m = ctx.magnification;
    const clouds = [0, 1].map(c => drawnPositions(ctx, k, c));
    const kept = [0, 1].map(c => st.removedBy[c].reduce((n, by) => n + !by, 0));
    const removed = st.removedBy[0].length - kept[0] + st.removedBy[1].length - kept[1];
    const t = s.arrays.tail.data, v = s.arrays.vector.data, n = s.arrays.magnitude.data.length;
    const tips = new Float32Array(3 * n), segments = new Float32Array(6 * n), colours = vectorColours(s, ctx.scale);
    const segmentColours = new Float32Array(6 * n);
    for (let i = 0; i < n; i++)
      for (let q = 0; q < 3; q++) {
        tips[3 * i + q] = t[3 * i + q] + m * v[3 * i + q];
        segments[6 * i + q] = t[3 * i + q];
        segments[6 * i + 3 + q] = tips[3 * i + q];
        segmentColours[6 * i + q] = segmentColours[6 * i + 3 + q] = colours[3 * i + q];
      }
    // this stage's corrections: arrows from where the stage before left the points to where it put them
    const moves = [], arrows = [];
    for (const c of [0, 1])
      for (const i of st.moves[c]) {
        const a = Array.from(st.before[c].subarray(3 * i, 3 * i + 3)), b = Array.from(st.xyz[c].subarray(3 * i, 3 * i + 3));
        moves.push([a, b]);
        pushArrow(arrows, a, b);
      }
    const moveColour = rgb(s.header.level ? stageColour(s.header.level) : "#000000");
    const origins = ctx.origins[k];
    return {
      stage: k, clouds, removedBy: st.removedBy, kept, removed, vectors: n, tips, segments, segmentColours, colours,
      moves, arrows: new Float32Array(arrows), arrowColours: new Float32Array(arrows.length).map((_, j) => moveColour[j % 3]),
      origins: new Float32Array(origins.flat()), originColours: new Float32Array([...rgb(ORIGIN_COLOURS[0]), ...rgb(ORIGIN_COLOURS[1])]),
    };
  }

  // The 3-D view's ground: a grid of round steps under the points (at their lowest z).
  function groundGrid(bounds) {
    const [bx, by, bz] = bounds, step = niceStep(Math.max(bx[1] - bx[0], by[1] - by[0]), 10), z = bz[0], lines = [];
    const x0 = Math.floor(bx[0] / step) * step, y0 = Math.floor(by[0] / step) * step;
    const x1 = Math.ceil(bx[1] / step) * step, y1 = Math.ceil(by[1] / step) * step;
    for (let x = x0; x <= x1 + 1e-9; x += step) lines.push(x, y0, z, x, y1, z);
    for (let y = y0; y <= y1 + 1e-9; y += step) lines.push(x0, y, z, x1, y, z);
    return { step, lines: new Float32Array(lines), colours: new Float32Array(lines.length).fill(0.85) };
  }

  function uploadFrame(v, f) {
    for (const c of [0, 1]) { upload(v, `xyz${c}`, f.clouds[c]); upload(v, `by${c}`, f.removedBy[c]); }
    for (const name of ["tips", "colours", "origins", "originColours"]) upload(v, name, f[name]);
    for (const [name, wide] of [["segments", wideLines(f.segments, f.segmentColours)], ["arrows", wideLines(f.arrows, f.arrowColours)]])
      for (const part of ["position", "other", "side", "rgb"]) upload(v, `${name}-${part}`, wide[part]);
  }

  function render(ctx, v) {
    const gl = v.gl, dpr = resize(v), aspect = v.canvas.width / v.canvas.height, f = ctx.frame, L = ctx.layers;
    v.mvp = viewMatrix(v.view, ctx.cameras[v.view], aspect);
    gl.viewport(0, 0, v.canvas.width, v.canvas.height);
    gl.clearColor(1, 1, 1, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    const three = v.view === "3d";
    // the top view draws in layer order (vectors over points), the 3-D view by depth
    if (three) gl.enable(gl.DEPTH_TEST); else gl.disable(gl.DEPTH_TEST);
    const C = v.coloured;
    gl.useProgram(C.p);
    gl.uniformMatrix4fv(C.loc.mvp, false, v.mvp);
    const draw = (mode, xyz, colours, size, round) => {
      const n = v.buffers[xyz].length / 3;
      if (!n) return;
      gl.useProgram(C.p);
      gl.uniform1f(C.loc.size, size * dpr);
      gl.uniform1f(C.loc.round, round ? 1 : 0);
      attribute(v, C.loc.position, xyz, 3);
      attribute(v, C.loc.rgb, colours, 3);
      gl.drawArrays(mode, 0, n);
      gl.disableVertexAttribArray(C.loc.rgb);
    };
    if (three) draw(gl.LINES, "grid", "gridColours", 1, false);
    const P = v.points;
    gl.useProgram(P.p);
    gl.uniformMatrix4fv(P.loc.mvp, false, v.mvp);
    gl.uniform3fv(P.loc.stageColours, new Float32Array(STAGE_COLOURS.flatMap(rgb)));
    gl.uniform1f(P.loc.sizeKept, (three ? 1.5 : 2) * dpr);
    gl.uniform1f(P.loc.sizeRemoved, (three ? 2.5 : 3) * dpr);
    gl.uniform1f(P.loc.showRemoved, L.removed ? 1 : 0);
    gl.uniform1f(P.loc.round, 0);
    for (const c of [0, 1]) {
      gl.uniform3fv(P.loc.kept, rgb(CLOUD_COLOURS[c]));
      gl.uniform1f(P.loc.showKept, L[`cloud${c + 1}`] ? 1 : 0);
      attribute(v, P.loc.position, `xyz${c}`, 3);
      attribute(v, P.loc.by, `by${c}`, 1, gl.UNSIGNED_BYTE);
      gl.drawArrays(gl.POINTS, 0, f.removedBy[c].length);
      gl.disableVertexAttribArray(P.loc.by); // the other program's attribute at this location has no such buffer
    }
    const W = v.wide;
    const drawWide = (name, width) => {
      const n = v.buffers[`${name}-side`].length;
      if (!n) return;
      gl.useProgram(W.p);
      gl.uniformMatrix4fv(W.loc.mvp, false, v.mvp);
      gl.uniform2f(W.loc.halfViewport, v.canvas.width / 2, v.canvas.height / 2);
      gl.uniform1f(W.loc.halfWidth, (width / 2) * dpr);
      gl.uniform1f(W.loc.round, 0);
      attribute(v, W.loc.position, `${name}-position`, 3);
      attribute(v, W.loc.other, `${name}-other`, 3);
      attribute(v, W.loc.side, `${name}-side`, 1);
      attribute(v, W.loc.rgb, `${name}-rgb`, 3);
      gl.drawArrays(gl.TRIANGLES, 0, n);
      for (const a of ["other", "side", "rgb"]) gl.disableVertexAttribArray(W.loc[a]);
    };
    if (L.corrections) drawWide("arrows", 1.5);
    if (L.vectors) { drawWide("segments", 2); draw(gl.POINTS, "tips", "colours", three ? 5 : 6, true); }
    if (L.origins) draw(gl.POINTS, "origins", "originColours", 11, true);
    drawOverlay(ctx, v, dpr);
  }

  // Screen position (CSS pixels in the view's box) of a point, or null behind the camera.
  function screenOf(v, x, y, z) {
    const [px, py, w] = project(v.mvp, x, y, z);
    if (w <= 0) return null;
    const r = v.box.getBoundingClientRect();
    return [(px + 1) / 2 * r.width, (1 - py) / 2 * r.height];
  }

  function drawOverlay(ctx, v, dpr) {
    const g = v.overlay.getContext("2d"), f = ctx.frame;
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, v.overlay.width, v.overlay.height);
    g.font = "12px sans-serif";
    if (ctx.layers.origins)
      for (let c = 0; c < 2; c++) {
        const p = screenOf(v, f.origins[3 * c], f.origins[3 * c + 1], f.origins[3 * c + 2]);
        // sensor 1's label to the left, sensor 2's to the right: the two are often close
        if (p) { g.fillStyle = ORIGIN_COLOURS[c]; g.textAlign = c ? "left" : "right"; g.fillText(`sensor ${c + 1}`, p[0] + (c ? 8 : -8), p[1] - 6); }
      }
    g.textAlign = "left";
    const ring = (i, colour) => {
      const p = i >= 0 && screenOf(v, f.tips[3 * i], f.tips[3 * i + 1], f.tips[3 * i + 2]);
      if (!p) return;
      g.strokeStyle = colour; g.lineWidth = 2.5;
      g.beginPath(); g.arc(p[0], p[1], 8, 0, 2 * Math.PI); g.stroke();
    };
    if (ctx.layers.vectors) { ring(selectedIndex(ctx), "#e00"); if (ctx.hovered && ctx.hovered.view === v.view) ring(ctx.hovered.index, "#000"); }
    const r = v.box.getBoundingClientRect();
    if (v.view === "top") {
      // the grid and its labels (x along the bottom, y up the left), in metres
      const c = ctx.cameras.top, s = r.height / (2 * c.half), step = niceStep(2 * c.half, 8);
      const toX = x => r.width / 2 + (x - c.centre[0]) * s, toY = y => r.height / 2 - (y - c.centre[1]) * s;
      const wx = r.width / (2 * s);
      g.strokeStyle = "rgba(0, 0, 0, 0.1)"; g.fillStyle = "#555"; g.lineWidth = 1;
      const label = x => String(+x.toFixed(6));
      for (let x = Math.ceil((c.centre[0] - wx) / step) * step; x <= c.centre[0] + wx; x += step) {
        g.beginPath(); g.moveTo(toX(x), 0); g.lineTo(toX(x), r.height); g.stroke();
        if (toX(x) > 30) g.fillText(label(x), toX(x) + 2, 12); // clear of the y labels
      }
      for (let y = Math.ceil((c.centre[1] - c.half) / step) * step; y <= c.centre[1] + c.half; y += step) {
        g.beginPath(); g.moveTo(0, toY(y)); g.lineTo(r.width, toY(y)); g.stroke();
        if (toY(y) > 20 && toY(y) < r.height - 40) g.fillText(label(y), 3, toY(y) - 2); // clear of the x labels and the scale bar
      }
      // a scale bar: a round length about a fifth of the width
      const metres = 2 * ctx.cameras.top.half * (r.width / r.height) / 5, p10 = 10 ** Math.floor(Math.log10(metres));
      const len = [5, 2, 1].map(s => s * p10).find(x => x <= metres), px = len / (2 * ctx.cameras.top.half) * r.height;
      g.strokeStyle = g.fillStyle = "#222"; g.lineWidth = 2;
      g.beginPath(); g.moveTo(12, r.height - 14); g.lineTo(12 + px, r.height - 14); g.stroke();
      g.fillText(`${len} m`, 12, r.height - 20);
      g.fillText("x →, y ↑", r.width - 60, r.height - 10);
    } else {
      g.fillStyle = "#555";
      g.fillText(`ground grid: ${ctx.grid.step} m`, 12, 16);
      // the axes' directions, from the corner
      const c = ctx.cameras["3d"], e = unit(sub(eyeOf(c), c.target)), right = unit(cross([0, 0, 1], e)), up = cross(e, right);
      const o = [40, r.height - 40];
      [["x", [1, 0, 0], "#d62728"], ["y", [0, 1, 0], "#2ca02c"], ["z", [0, 0, 1], "#1f77b4"]].forEach(([name, a, colour]) => {
        const p = [o[0] + 25 * dot(a, right), o[1] - 25 * dot(a, up)];
        g.strokeStyle = g.fillStyle = colour; g.lineWidth = 2;
        g.beginPath(); g.moveTo(...o); g.lineTo(...p); g.stroke();
        g.fillText(name, p[0] + 2, p[1] - 2);
      });
    }
  }

  // The vector drawn nearest a point of the view's box (CSS pixels), within 8 px of its line
  // from tail to tip on the screen: its index, or -1.
  function pick(ctx, v, x, y) {
    const f = ctx.frame, r = v.box.getBoundingClientRect(), m = v.mvp, g = f.segments;
    const screen = (k) => {
      const [px, py, w] = project(m, g[k], g[k + 1], g[k + 2]);
      return [(px + 1) / 2 * r.width, (1 - py) / 2 * r.height, w];
    };
    let best = -1, bestD = 64, bestW = Infinity;
    for (let i = 0; i < f.vectors; i++) {
      const [ax, ay, aw] = screen(6 * i), [bx, by, bw] = screen(6 * i + 3);
      if (aw <= 0 || bw <= 0) continue;
      const dx = bx - ax, dy = by - ay, len2 = dx * dx + dy * dy;
      const t = len2 > 0 ? Math.max(0, Math.min(1, ((x - ax) * dx + (y - ay) * dy) / len2)) : 0;
      const ex = ax + t * dx - x, ey = ay + t * dy - y, d = ex * ex + ey * ey, w = aw + t * (bw - aw);
      // of vectors drawn on one another, the nearest the camera
      if (d < bestD - 1e-9 || (Math.abs(d - bestD) < 1e-9 && w < bestW)) { best = i; bestD = d; bestW = w; }
    }
    return best;
  }

  function selectedIndex(ctx) {
    if (ctx.selected === null) return -1;
    return Array.prototype.indexOf.call(ctx.stages[ctx.stage].arrays.voxel.data, ctx.selected);
  }

  // ---- the page ----
  function autoMagnification(bounds, stages) {
    let top = 0;
    for (const s of stages) if (s) top = Math.max(top, s.header.max_magnitude);
    const span = Math.max(bounds[0][1] - bounds[0][0], bounds[1][1] - bounds[1][0]);
    if (!(top > 0) || !Number.isFinite(span)) return 1;
    // as the static figures: the largest vector about 1/16 of the view, a round number, never shrunk
    const x = span / 16 / top, power = 10 ** Math.floor(Math.log10(x));
    for (const step of [5, 2, 1]) if (step * power <= x) return Math.max(1, step * power);
    return Math.max(1, power);
  }

  // The extent of the points, 5% wider.
  function bounds(xyzs) {
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const xyz of xyzs)
      for (let i = 0; i < xyz.length; i += 3)
        for (let k = 0; k < 3; k++) { const x = xyz[i + k]; if (x < lo[k]) lo[k] = x; if (x > hi[k]) hi[k] = x; }
    return lo.map((l, k) => {
      const pad = Number.isFinite(l) ? 0.05 * Math.max(hi[k] - l, 1) : 1;
      return Number.isFinite(l) ? [l - pad, hi[k] + pad] : [-1, 1];
    });
  }

  function title(ctx, view) {
    const s = ctx.stages[ctx.stage];
    return (view === "top" ? "from above · " : "") + `${ctx.pair} · stage ${String(s.header.level).padStart(2, "0")} ${s.header.hypothesis}` +
      ` · largest vector ${fmt(s.header.max_magnitude, 3)} m · vectors ×${ctx.magnification}`;
  }

  function budgetText(ctx) {
    const p = ctx.points.header, s = ctx.stages[ctx.stage];
    const parts = p.clouds.map((c, i) => `cloud ${i + 1}: ${count(ctx.pts.n[i])} of ${count(c.total)} points drawn`);
    let text = parts.join("; ");
    if (ctx.pts.n.some((n, i) => n < p.clouds[i].total))
      text += ` (a fixed sample of at most ${count(p.budget)} a cloud, <code>report.explorer_points</code> in the ` +
        "config; the button draws every point)";
    if (s.header.clouds) {
      const drawn = (c, what) => s.arrays[`${what}${c + 1}`].data.filter(i => i < ctx.pts.n[c]).length;
      const r = s.header.clouds.map((c, i) => `${count(drawn(i, "removed"))} of the ${count(c.removed.total)} points of cloud ${i + 1}` +
        (c.moved.total ? `, moved ${count(drawn(i, "moved"))} of ${count(c.moved.total)}` : ""));
      text += `. This stage removed ${r.join(" and ")} (drawn of all)`;
    }
    return text + ".";
  }

  function selectedText(ctx) {
    if (ctx.selected === null) return "Click a vector to select its voxel; the selection stays when the stage changes.";
    const i = selectedIndex(ctx);
    return i < 0 ? `voxel ${ctx.selected}: no valid vector at this stage` : "selected: " + voxelText(ctx.stages[ctx.stage], i);
  }

  function legendHtml(ctx) {
    const sw = (colour, text) => `<span><span class="swatch" style="background:${colour}"></span>${text}</span>`;
    const sc = ctx.scale, parts = [];
    if (sc.kind === "tag") parts.push("vectors by first tag: " + sc.names.map((name, k) => sw(TAG_COLOURS[k % TAG_COLOURS.length], name)).join(" "));
    else {
      const stops = SCALES[sc.kind].map((c, k, all) => `${c} ${(100 * k / (all.length - 1)).toFixed(0)}%`).join(", ");
      parts.push(`<span class="scale">vectors by ${sc.kind === "z" ? "|z|" : "|d| (m)"}: 0<span class="bar" ` +
        `style="background:linear-gradient(to right, ${stops})"></span>${fmt(sc.top, sc.kind === "z" ? 1 : 3)}</span>`);
    }
    parts.push(sw(CLOUD_COLOURS[0], "cloud 1"), sw(CLOUD_COLOURS[1], "cloud 2"));
    ctx.stages.forEach((s, k) => { if (s && s.header.level) parts.push(sw(stageColour(s.header.level), `removed / moved by ${ctx.labels[k]}`)); });
    return parts.join(" ");
  }

  function control(tag, props, parent) {
    const el = document.createElement(tag);
    Object.assign(el, props);
    if (parent) parent.appendChild(el);
    return el;
  }

  // Draw both views at the next animation frame (many events, one draw).
  function request(ctx) {
    if (ctx.pending) return ctx.pending;
    ctx.pending = new Promise(resolve => requestAnimationFrame(() => {
      ctx.pending = null;
      for (const v of ctx.views) render(ctx, v);
      resolve();
    }));
    return ctx.pending;
  }

  // A new stage, colour or magnification: the frame anew, uploaded to both views.
  function update(ctx) {
    performance.mark("explorer update");
    ctx.ui.label.textContent = ctx.labels[ctx.stage];
    ctx.frame = frame(ctx);
    for (const v of ctx.views) { uploadFrame(v, ctx.frame); v.title.textContent = title(ctx, v.view); }
    ctx.ui.budget.innerHTML = budgetText(ctx);
    ctx.ui.selected.innerHTML = selectedText(ctx);
    ctx.ui.legend.innerHTML = legendHtml(ctx);
    ctx.hovered = null;
    for (const v of ctx.views) v.tooltip.hidden = true;
    return request(ctx);
  }

  // Orbit, pan and zoom with the mouse; hover and click pick a vector.
  function interact(ctx, v) {
    let drag = null;
    const cam = () => ctx.cameras[v.view];
    const local = e => { const r = v.box.getBoundingClientRect(); return [e.clientX - r.left, e.clientY - r.top]; };
    v.canvas.addEventListener("contextmenu", e => e.preventDefault());
    v.canvas.addEventListener("pointerdown", e => {
      drag = { x: e.clientX, y: e.clientY, pan: v.view === "top" || e.shiftKey || e.button !== 0, moved: false };
      v.canvas.setPointerCapture(e.pointerId);
    });
    v.canvas.addEventListener("pointerup", e => {
      const click = drag && !drag.moved;
      drag = null;
      if (!click) return;
      const [x, y] = local(e), i = ctx.layers.vectors ? pick(ctx, v, x, y) : -1;
      if (i >= 0) { ctx.selected = ctx.stages[ctx.stage].arrays.voxel.data[i]; ctx.ui.selected.innerHTML = selectedText(ctx); request(ctx); }
    });
    v.canvas.addEventListener("pointermove", e => {
      if (drag) {
        const dx = e.clientX - drag.x, dy = e.clientY - drag.y, c = cam(), h = v.box.getBoundingClientRect().height;
        if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
        drag.x = e.clientX; drag.y = e.clientY;
        if (v.view === "top") { const s = 2 * c.half / h; c.centre[0] -= dx * s; c.centre[1] += dy * s; }
        else if (drag.pan) {
          const e3 = unit(sub(eyeOf(c), c.target)), right = unit(cross([0, 0, 1], e3)), up = cross(e3, right);
          const s = 2 * c.distance * Math.tan(FOV / 2) / h;
          for (let k = 0; k < 3; k++) c.target[k] += s * (-dx * right[k] + dy * up[k]);
        } else {
          c.azimuth -= dx * 0.008;
          c.elevation = Math.max(-1.55, Math.min(1.55, c.elevation + dy * 0.008));
        }
        cameraMoved(ctx, v.view);
        return;
      }
      hover(ctx, v, ...local(e));
    });
    v.canvas.addEventListener("pointerleave", () => { if (ctx.hovered) { ctx.hovered = null; v.tooltip.hidden = true; request(ctx); } });
    v.canvas.addEventListener("wheel", e => {
      e.preventDefault();
      const c = cam(), factor = Math.exp(e.deltaY * 0.0015);
      if (v.view === "top") {
        // zoom about the cursor: the point under it stays
        const [x, y] = local(e), r = v.box.getBoundingClientRect(), s = 2 * c.half / r.height;
        const wx = c.centre[0] + (x - r.width / 2) * s, wy = c.centre[1] - (y - r.height / 2) * s;
        c.half *= factor;
        c.centre = [wx - (wx - c.centre[0]) * factor, wy - (wy - c.centre[1]) * factor];
      } else c.distance *= factor;
      cameraMoved(ctx, v.view);
    }, { passive: false });
    v.canvas.addEventListener("dblclick", () => { ctx.cameras[v.view] = homeCamera(v.view, ctx.bounds, v.canvas.width / v.canvas.height); cameraMoved(ctx, v.view); });
  }

  function hover(ctx, v, x, y) {
    const i = ctx.layers.vectors ? pick(ctx, v, x, y) : -1;
    const was = ctx.hovered;
    ctx.hovered = i >= 0 ? { view: v.view, index: i } : null;
    if (i >= 0) {
      v.tooltip.innerHTML = voxelText(ctx.stages[ctx.stage], i);
      v.tooltip.hidden = false;
      const r = v.box.getBoundingClientRect();
      v.tooltip.style.left = `${Math.min(x + 12, r.width - v.tooltip.offsetWidth - 4)}px`;
      v.tooltip.style.top = `${Math.max(y - v.tooltip.offsetHeight - 8, 4)}px`;
    } else v.tooltip.hidden = true;
    if ((was ? was.index : -1) !== i) request(ctx);
  }

  function cameraMoved(ctx, view) {
    request(ctx);
    if (ctx.onCamera) ctx.onCamera(view);
  }

  // The view as a PNG (data URL): the WebGL canvas, the overlay and the title, on white.
  function png(ctx, v) {
    const w = v.canvas.width, h = v.canvas.height, head = 24 * (window.devicePixelRatio || 1);
    const out = control("canvas", { width: w, height: h + head });
    const g = out.getContext("2d");
    g.fillStyle = "#fff"; g.fillRect(0, 0, w, h + head);
    g.drawImage(v.canvas, 0, head); g.drawImage(v.overlay, 0, head);
    g.fillStyle = "#000"; g.font = `${Math.round(head * 0.55)}px sans-serif`;
    g.fillText(title(ctx, v.view), 6, head * 0.72);
    return out.toDataURL("image/png");
  }

  // the stage a link asks for (report.html#stage=2: the overview's heat map cells link so), else 0
  function initialStage() {
    const m = /stage=(\d+)/.exec(location.hash);
    return m ? +m[1] : 0;
  }

  // A data script, loaded by a script element (file:// pages may load scripts, not fetch files):
  // resolves true when it ran, false when it is missing.
  function loadScript(src) {
    return new Promise(resolve => {
      const el = document.createElement("script");
      el.src = src;
      el.onload = () => resolve(true);
      el.onerror = () => resolve(false);
      document.head.appendChild(el);
    });
  }

  // Each explorer's data, one script after another (two explorers of one page, as in
  // lidarfield compare, may hold keys of the same name): its blobs by key.
  let queue = Promise.resolve();
  function loadData(scripts, mine) {
    queue = queue.then(async () => {
      for (const src of scripts) {
        blobs = mine;
        await loadScript(src);
      }
    });
    return queue.then(() => mine);
  }

  // The points drawn: the sample, and the rest once loaded ("show all").
  function setPoints(ctx, rest) {
    const a = ctx.points.arrays;
    const join = (x, y) => { const out = new Float32Array(x.length + y.length); out.set(x); out.set(y, x.length); return out; };
    const xyz = rest ? [join(a.xyz1.data, rest.arrays.xyz1.data), join(a.xyz2.data, rest.arrays.xyz2.data)] : [a.xyz1.data, a.xyz2.data];
    ctx.pts = { xyz, n: xyz.map(x => x.length / 3) };
    ctx.states = stageStates(ctx.pts, ctx.stages);
    ctx.anyMoves = ctx.states.some(st => st && (st.moves[0].length || st.moves[1].length));
  }

  async function showAll(ctx, spec, button) {
    button.disabled = true;
    button.textContent = "loading every point…";
    const mine = await loadData([spec.rest], {});
    if (!mine.rest) {
      button.textContent = "every point: explorer/rest.js is not written";
      return;
    }
    setPoints(ctx, decode(mine.rest));
    button.hidden = true;
    await update(ctx);
    ctx.root.dataset.allPoints = "1";
  }

  function build(root, blobs) {
    const spec = JSON.parse(root.querySelector("script[type='application/json']").textContent);
    const note = control("p", { className: "note" }, root);
    if (!blobs.points) {
      note.innerHTML = "The explorer's points (explorer/points.js) are not written: " + spec.how;
      return null;
    }
    const points = decode(blobs.points);
    const stages = spec.stages.map(s => (blobs[s.id] ? decode(blobs[s.id]) : null));
    const missing = spec.stages.filter((s, i) => !stages[i]).map(s => s.id);
    if (missing.length) note.innerHTML = `Not written yet: the explorer data of ${missing.join(", ")}. ` + spec.how;
    if (!stages.some(Boolean)) return null;
    const origin = T => [[0, 0, 0], T ? [T[0][3], T[1][3], T[2][3]] : [0, 0, 0]];
    const ctx = {
      root, pair: spec.pair, ids: spec.stages.map(s => s.id), labels: spec.stages.map(s => s.label), points, stages,
      origins: stages.map(s => origin(s ? s.header.T_1_2 : points.header.T_1_2)), colourBy: "magnitude", selected: null,
      hovered: null, stage: 0, layers: Object.fromEntries(LAYERS.map(([k]) => [k, true])), ui: {}, views: [], cameras: {},
    };
    setPoints(ctx, null);
    ctx.bounds = bounds(ctx.pts.xyz);
    ctx.magnification = autoMagnification(ctx.bounds, stages);
    ctx.scale = colourScale(ctx.colourBy, stages);
    // the stage asked for, else the first written one
    const wanted = Math.min(initialStage(), stages.length - 1);
    ctx.stage = stages[wanted] ? wanted : stages.findIndex(Boolean);

    const bar = control("div", { className: "explorer-controls" }, root);
    control("span", { textContent: "stage " }, bar);
    const slider = ctx.ui.slider = control("input", { type: "range", min: 0, max: stages.length - 1, step: 1, value: ctx.stage, className: "stage-slider" }, bar);
    ctx.ui.label = control("strong", { className: "stage-label" }, bar);
    control("span", { textContent: " · colour by " }, bar);
    const colour = control("select", { className: "colour-by" }, bar);
    for (const [v, t] of [["magnitude", "magnitude |d|"], ["z", "significance |z|"], ["tag", "tag"]]) control("option", { value: v, textContent: t }, colour);
    control("span", { textContent: " · vectors × " }, bar);
    const mag = control("input", { type: "number", min: 0, step: "any", value: ctx.magnification, className: "magnification", style: "width:5em" }, bar);
    const toggles = control("div", { className: "explorer-controls" }, root);
    for (const [key, text] of LAYERS) {
      const label = control("label", {}, toggles);
      const box = control("input", { type: "checkbox", checked: true, className: "layer", value: key }, label);
      label.append(" " + text + " ");
      box.addEventListener("change", () => { ctx.layers[key] = box.checked; request(ctx); });
    }
    ctx.ui.legend = control("div", { className: "explorer-legend" }, root);
    const budget = control("div", { className: "explorer-controls" }, root);
    ctx.ui.budget = control("span", { className: "note budget-drawn" }, budget);
    if (ctx.pts.n.some((n, i) => n < points.header.clouds[i].total)) {
      const all = points.header.clouds.reduce((n, c) => n + c.total, 0);
      const button = control("button", { type: "button", className: "show-all", textContent: `draw all ${count(all)} points` }, budget);
      button.addEventListener("click", () => showAll(ctx, spec, button));
    }
    const views = control("div", { className: "explorer-views" }, root);
    for (const view of ["3d", "top"]) {
      const box = control("div", { className: "explorer-view" }, views);
      const heading = control("div", { className: "explorer-title" }, box);
      const area = control("div", { className: `explorer-canvas explorer-${view}` }, box);
      const v = makeView(view, area);
      if (!v) {
        views.remove();
        note.innerHTML = "This browser gives the page no WebGL, so the explorer cannot draw; the stage figures below show the same stages.";
        return null;
      }
      v.title = heading;
      ctx.views.push(v);
      const button = control("button", { type: "button", className: `png png-${view}`, textContent: `PNG of the ${view === "3d" ? "3-D view" : "top view"}` }, box);
      button.addEventListener("click", () => {
        const a = control("a", { href: png(ctx, v), download: `${ctx.pair}-${ctx.ids[ctx.stage]}-${view}.png` });
        a.click();
      });
    }
    ctx.grid = groundGrid(ctx.bounds);
    for (const v of ctx.views) {
      upload(v, "grid", ctx.grid.lines);
      upload(v, "gridColours", ctx.grid.colours);
      const r = v.box.getBoundingClientRect();
      ctx.cameras[v.view] = homeCamera(v.view, ctx.bounds, r.width / Math.max(r.height, 1));
      interact(ctx, v);
    }
    ctx.ui.selected = control("p", { className: "selected-voxel" }, root);
    slider.addEventListener("input", () => {
      const k = +slider.value;
      if (!stages[k]) { ctx.ui.label.textContent = `${ctx.labels[k]}: not written (its explorer job has not run)`; return; }
      ctx.stage = k;
      history.replaceState(null, "", `#stage=${ctx.stage}`); // a link to this stage of the pair
      update(ctx);
    });
    colour.addEventListener("change", () => { ctx.colourBy = colour.value; ctx.scale = colourScale(ctx.colourBy, stages); update(ctx); });
    mag.addEventListener("change", () => { if (+mag.value > 0) { ctx.magnification = +mag.value; update(ctx); } });
    new ResizeObserver(() => request(ctx)).observe(views);
    ctx.png = view => png(ctx, ctx.views.find(v => v.view === view));
    // where a point, or a vector's tip, is drawn in a view, in the page's pixels (the tests hover there)
    ctx.onPage = (view, x, y, z) => {
      const v = ctx.views.find(w => w.view === view), p = screenOf(v, x, y, z), r = v.box.getBoundingClientRect();
      return p && [r.left + p[0], r.top + p[1]];
    };
    ctx.tipOnPage = (view, i) => ctx.onPage(view, ...ctx.frame.tips.subarray(3 * i, 3 * i + 3));
    ctx.update = () => update(ctx);
    ctx.request = () => request(ctx);
    ctx.ready = update(ctx).then(() => {
      root.dataset.readyMs = performance.now().toFixed(0); // open to interactive (bench/explorer.py)
      root.dataset.ready = "1";
    });
    root.explorer = ctx;
    return ctx;
  }

  window.lidarfieldExplorer = {
    add(key, b64) { blobs[key] = b64; },
    decode,
    build,
  };

  // Explorers of one group (data-link) share their cameras and their stage: lidarfield compare.
  function link(contexts) {
    for (const ctx of contexts) {
      const others = contexts.filter(c => c !== ctx);
      ctx.onCamera = view => {
        for (const o of others) { o.cameras[view] = JSON.parse(JSON.stringify(ctx.cameras[view])); request(o); }
      };
      ctx.ui.slider.addEventListener("input", () => {
        for (const o of others) {
          const k = Math.min(ctx.stage, o.stages.length - 1);
          if (!o.stages[k]) continue;
          o.ui.slider.value = k;
          o.stage = k;
          update(o);
        }
      });
    }
  }

  document.addEventListener("DOMContentLoaded", () => {
    const groups = {};
    for (const root of document.querySelectorAll(".explorer")) {
      const spec = JSON.parse(root.querySelector("script[type='application/json']").textContent);
      const built = loadData(spec.scripts, {}).then(mine => {
        performance.mark("explorer data loaded");
        const ctx = build(root, mine);
        return ctx && ctx.ready.then(() => ctx);
      });
      if (root.dataset.link) (groups[root.dataset.link] = groups[root.dataset.link] || []).push(built);
    }
    for (const group of Object.values(groups))
      Promise.all(group).then(contexts => {
        if (!contexts.every(Boolean)) return;
        link(contexts);
        for (const ctx of contexts) ctx.root.dataset.linked = "1";
      });
  });
})();
