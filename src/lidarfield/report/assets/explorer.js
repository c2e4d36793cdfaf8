// lidarfield's pair explorer: one pair's stages in a 3-D view and a top view, with a stage slider.
// Opens from file:// with no network: the data comes in as scripts (explorer/*.js) that call
// lidarfieldExplorer.add(key, base64 blob); see lidarfield.report.explorer_data for the format.
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

  const CLOUD_COLOUR = { 1: "#a8a8a8", 2: "#7f9cc0" };
  // one colour per stage for the points it removed and the corrections it made (stage 1 first)
  const STAGE_COLOURS = ["#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22"];
  const TAG_COLOURS = ["#bbbbbb", "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2"];
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
  const stageColour = level => STAGE_COLOURS[(level - 1) % STAGE_COLOURS.length];

  // The points of every stage: which sampled points are left (0) or which stage removed them,
  // and where the left ones are (a stage that moves points gets its own copy).
  function stageStates(points, stages) {
    const states = [];
    let removedBy = [new Uint16Array(points.n[0]), new Uint16Array(points.n[1])];
    let xyz = [points.xyz[0], points.xyz[1]];
    let before = xyz;
    for (const s of stages) {
      if (!s) { states.push(null); continue; }
      removedBy = removedBy.map(a => a.slice());
      before = xyz;
      for (const c of [0, 1]) {
        const removed = s.arrays[`removed${c + 1}`];
        if (removed) for (const i of removed.data) removedBy[c][i] = s.header.level;
        const moved = s.arrays[`moved${c + 1}`];
        if (moved && moved.data.length) {
          const to = s.arrays[`moved${c + 1}_xyz`].data, copy = xyz[c].slice();
          moved.data.forEach((i, k) => copy.set(to.subarray(3 * k, 3 * k + 3), 3 * i));
          xyz = c === 0 ? [copy, xyz[1]] : [xyz[0], copy];
        }
      }
      states.push({ removedBy, xyz, before });
    }
    return states;
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

  function colourOf(s, mode) {
    const a = s.arrays, n = a.magnitude.data.length, out = new Float64Array(n);
    for (let i = 0; i < n; i++) {
      if (mode === "magnitude") out[i] = a.magnitude.data[i];
      else if (mode === "z") out[i] = a.z ? Math.abs(a.z.data[i]) : NaN;
      else {
        const bits = a.tags.data[i];
        out[i] = bits ? Math.clz32(1) - Math.clz32(bits & -bits) + 1 : 0; // its first tag, 1-based
      }
    }
    return out;
  }

  function colourScale(mode, stages) {
    const loaded = stages.filter(Boolean);
    if (mode === "tag") {
      const tags = loaded.length ? loaded[0].header.tags : [];
      const names = ["no tag", ...tags];
      const scale = [];
      names.forEach((_, k) => {
        const c = TAG_COLOURS[k % TAG_COLOURS.length];
        scale.push([k / names.length, c], [(k + 1) / names.length, c]);
      });
      return {
        colorscale: scale, cmin: -0.5, cmax: names.length - 0.5,
        colorbar: { title: { text: "first tag" }, tickvals: names.map((_, k) => k), ticktext: names },
      };
    }
    const key = mode === "z" ? "z" : "magnitude";
    let top = 1e-9;
    for (const s of loaded) if (s.arrays[key]) for (const v of s.arrays[key].data) if (Math.abs(v) > top) top = Math.abs(v);
    return {
      colorscale: mode === "z" ? "Plasma" : "Viridis", cmin: 0, cmax: top,
      colorbar: { title: { text: mode === "z" ? "|z|" : "|d| (m)" } },
    };
  }

  function autoMagnification(points, stages) {
    let lo = [Infinity, Infinity], hi = [-Infinity, -Infinity], top = 0;
    for (const xyz of points.xyz)
      for (let i = 0; i < xyz.length; i += 3)
        for (const k of [0, 1]) { lo[k] = Math.min(lo[k], xyz[i + k]); hi[k] = Math.max(hi[k], xyz[i + k]); }
    for (const s of stages) if (s) top = Math.max(top, s.header.max_magnitude);
    const span = Math.max(hi[0] - lo[0], hi[1] - lo[1]);
    if (!(top > 0) || !Number.isFinite(span)) return 1;
    // as the static figures: the largest vector about 1/16 of the view, a round number, never shrunk
    const x = span / 16 / top, power = 10 ** Math.floor(Math.log10(x));
    for (const step of [5, 2, 1]) if (step * power <= x) return Math.max(1, step * power);
    return Math.max(1, power);
  }

  // The traces of one stage, in a fixed order (their indices are the layers' on both views).
  function traces(view, ctx, k) {
    const s = ctx.stages[k], st = ctx.states[k], three = view === "3d";
    const type = three ? "scatter3d" : "scattergl";
    const xyzOf = (arr, idx) => {
      const n = idx.length, x = new Float32Array(n), y = new Float32Array(n), z = new Float32Array(n);
      idx.forEach((i, j) => { x[j] = arr[3 * i]; y[j] = arr[3 * i + 1]; z[j] = arr[3 * i + 2]; });
      return three ? { x, y, z } : { x, y };
    };
    const out = [];
    for (const c of [0, 1]) {
      const keep = [];
      st.removedBy[c].forEach((by, i) => { if (!by) keep.push(i); });
      out.push({
        type, mode: "markers", name: LAYERS[c][1], ...xyzOf(st.xyz[c], keep), hoverinfo: "skip",
        marker: { size: three ? 1.5 : 2, color: CLOUD_COLOUR[c + 1] },
      });
    }
    // removed points: by stages 1..k, each in its stage's colour, where they were when removed
    const rx = [], ry = [], rz = [], rc = [];
    for (const c of [0, 1])
      st.removedBy[c].forEach((by, i) => {
        if (!by) return;
        const at = ctx.states[by].before[c];
        rx.push(at[3 * i]); ry.push(at[3 * i + 1]); rz.push(at[3 * i + 2]); rc.push(stageColour(by));
      });
    out.push({
      type, mode: "markers", name: LAYERS[2][1], x: rx, y: ry, ...(three ? { z: rz } : {}), hoverinfo: "skip",
      marker: { size: three ? 2 : 3, color: rc },
    });
    // corrections: this stage's moved points, a segment from before to after
    const cx = [], cy = [], cz = [];
    for (const c of [0, 1]) {
      const moved = s.arrays[`moved${c + 1}`];
      if (!moved) continue;
      moved.data.forEach(i => {
        const b = st.before[c], a = st.xyz[c];
        cx.push(b[3 * i], a[3 * i], NaN); cy.push(b[3 * i + 1], a[3 * i + 1], NaN); cz.push(b[3 * i + 2], a[3 * i + 2], NaN);
      });
    }
    out.push({
      type, mode: "lines", name: LAYERS[3][1], x: cx, y: cy, ...(three ? { z: cz } : {}), hoverinfo: "skip",
      line: { width: 2, color: s.header.level ? stageColour(s.header.level) : "#000" },
    });
    // vectors: tail (mean of cloud 1) to tail + magnification x vector; hover on the tips
    const t = s.arrays.tail.data, v = s.arrays.vector.data, n = s.arrays.magnitude.data.length, m = ctx.magnification;
    const colour = colourOf(s, ctx.colourBy), scale = colourScale(ctx.colourBy, ctx.stages);
    const lx = [], ly = [], lz = [], lc = [], tx = new Float32Array(n), ty = new Float32Array(n), tz = new Float32Array(n);
    for (let i = 0; i < n; i++) {
      tx[i] = t[3 * i] + m * v[3 * i]; ty[i] = t[3 * i + 1] + m * v[3 * i + 1]; tz[i] = t[3 * i + 2] + m * v[3 * i + 2];
      lx.push(t[3 * i], tx[i], NaN); ly.push(t[3 * i + 1], ty[i], NaN); lz.push(t[3 * i + 2], tz[i], NaN);
      lc.push(colour[i], colour[i], colour[i]);
    }
    out.push({
      type, mode: "lines", name: "vectors", x: lx, y: ly, ...(three ? { z: lz } : {}), hoverinfo: "skip",
      line: three ? { width: 5, color: lc, colorscale: scale.colorscale, cmin: scale.cmin, cmax: scale.cmax }
        : { width: 1.5, color: "rgba(40,40,40,0.8)" },
    });
    out.push({
      type, mode: "markers", name: "vector tips", x: tx, y: ty, ...(three ? { z: tz } : {}),
      hovertext: ctx.hover[k], hovertemplate: "%{hovertext}<extra></extra>", customdata: Array.from(s.arrays.voxel.data),
      marker: { size: three ? 3 : 7, color: colour, ...scale, showscale: three },
    });
    const o = ctx.origins[k];
    out.push({
      type, mode: "markers+text", name: LAYERS[5][1], x: [o[0][0], o[1][0]], y: [o[0][1], o[1][1]],
      ...(three ? { z: [o[0][2], o[1][2]] } : {}), text: ["sensor 1", "sensor 2"], textposition: "top center",
      marker: { size: three ? 6 : 10, symbol: "diamond", color: ["#444", "#466ea0"] }, hoverinfo: "text",
    });
    // the selected voxel, ringed (kept when the slider moves: the same voxel at the new stage)
    const sel = ctx.selected === null ? -1 : Array.prototype.indexOf.call(s.arrays.voxel.data, ctx.selected);
    out.push({
      type, mode: "markers", name: "selected voxel", hoverinfo: "skip",
      x: sel < 0 ? [] : [tx[sel]], y: sel < 0 ? [] : [ty[sel]], ...(three ? { z: sel < 0 ? [] : [tz[sel]] } : {}),
      marker: { size: three ? 9 : 16, color: "rgba(0,0,0,0)", line: { color: "#e00", width: 3 }, symbol: "circle-open" },
    });
    const layerOf = ["cloud1", "cloud2", "removed", "corrections", "vectors", "vectors", "origins", "vectors"];
    out.forEach((tr, i) => { tr.visible = ctx.layers[layerOf[i]]; tr.showlegend = false; });
    return out;
  }

  // The extent of the sampled points, 5% wider: fixed axes, so that stages are drawn to one scale.
  function bounds(points) {
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const xyz of points.xyz)
      for (let i = 0; i < xyz.length; i += 3)
        for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], xyz[i + k]); hi[k] = Math.max(hi[k], xyz[i + k]); }
    return lo.map((l, k) => {
      const pad = Number.isFinite(l) ? 0.05 * Math.max(hi[k] - l, 1) : 1;
      return Number.isFinite(l) ? [l - pad, hi[k] + pad] : [-1, 1];
    });
  }

  function layout(view, ctx, k) {
    const s = ctx.stages[k];
    const title = `${ctx.pair} · stage ${String(s.header.level).padStart(2, "0")} ${s.header.hypothesis}` +
      ` · largest vector ${fmt(s.header.max_magnitude, 3)} m · vectors ×${ctx.magnification}`;
    // uirevision: Plotly keeps the camera (3-D) and the zoom (top view) across redraws
    const base = { title: { text: (view === "3d" ? "" : "from above · ") + title, font: { size: 13 } },
      uirevision: "explorer", margin: { l: 0, r: 0, t: 30, b: 0 }, hovermode: "closest" };
    // the view as the analyst left it (camera, zoom) when it was drawn before, else the points' extent
    const full = ctx.ui[view]._fullLayout, b = ctx.bounds, axis = (k, name) => ({ title: { text: `${name} (m)` },
      range: full && full[`${name}axis`] ? full[`${name}axis`].range.slice() : b[k].slice() });
    if (view === "3d") {
      const span = Math.max(...b.map(r => r[1] - r[0]));
      const scene = { aspectmode: "manual", xaxis: { title: { text: "x (m)" }, range: b[0] }, yaxis: { title: { text: "y (m)" },
        range: b[1] }, zaxis: { title: { text: "z (m)" }, range: b[2] },
        aspectratio: { x: (b[0][1] - b[0][0]) / span, y: (b[1][1] - b[1][0]) / span, z: (b[2][1] - b[2][0]) / span } };
      if (full && full.scene) scene.camera = JSON.parse(JSON.stringify(full.scene.camera));
      return { ...base, scene };
    }
    return { ...base, margin: { l: 50, r: 10, t: 30, b: 40 }, xaxis: axis(0, "x"), yaxis: { ...axis(1, "y"), scaleanchor: "x" } };
  }

  function budgetText(ctx, k) {
    const p = ctx.points.header, s = ctx.stages[k];
    const parts = p.clouds.map((c, i) =>
      `cloud ${i + 1}: ${count(c.drawn)} of ${count(c.total)} points drawn`);
    let text = parts.join("; ");
    if (p.clouds.some(c => c.drawn < c.total))
      text += ` (a fixed sample of at most ${count(p.budget)} a cloud: <code>report.explorer_points</code> in the ` +
        "config, 0 for every point)";
    if (s.header.clouds) {
      const r = s.header.clouds.map((c, i) => `${count(c.removed.drawn)} of the ${count(c.removed.total)} points of cloud ${i + 1}` +
        (c.moved.total ? `, moved ${count(c.moved.drawn)} of ${count(c.moved.total)}` : ""));
      text += `. This stage removed ${r.join(" and ")} (drawn of all)`;
    }
    return text + ".";
  }

  function selectedText(ctx, k) {
    if (ctx.selected === null) return "Click a vector tip to select its voxel; the selection stays when the stage changes.";
    const s = ctx.stages[k], i = Array.prototype.indexOf.call(s.arrays.voxel.data, ctx.selected);
    return i < 0 ? `voxel ${ctx.selected}: no valid vector at this stage` : "selected: " + voxelText(s, i);
  }

  function draw(ctx) {
    const k = ctx.stage;
    performance.mark("explorer draw");
    ctx.ui.label.textContent = ctx.labels[k];
    if (!ctx.stages[k]) {
      ctx.ui.budget.innerHTML = `The data of stage ${ctx.labels[k]} is not written (its explorer job has not run).`;
      return Promise.resolve();
    }
    ctx.ui.budget.innerHTML = budgetText(ctx, k);
    ctx.ui.selected.innerHTML = selectedText(ctx, k);
    const config = { responsive: true, displaylogo: false,
      toImageButtonOptions: { format: "png", filename: `${ctx.pair}-${ctx.ids[k]}`, scale: 2 } };
    return Promise.all(["3d", "top"].map(view => Plotly.react(ctx.ui[view], traces(view, ctx, k), layout(view, ctx, k), config)));
  }

  // the stage a link asks for (report.html#stage=2: the overview's heat map cells link so), else 0
  function initialStage() {
    const m = /stage=(\d+)/.exec(location.hash);
    return m ? +m[1] : 0;
  }

  function control(tag, props, parent) {
    const el = document.createElement(tag);
    Object.assign(el, props);
    if (parent) parent.appendChild(el);
    return el;
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
  function loadData(spec) {
    const mine = {};
    queue = queue.then(async () => {
      for (const src of spec.scripts) {
        blobs = mine;
        await loadScript(src);
      }
    });
    return queue.then(() => mine);
  }

  function build(root, blobs) {
    const spec = JSON.parse(root.querySelector("script[type='application/json']").textContent);
    const note = control("p", { className: "note" }, root);
    if (typeof Plotly === "undefined") {
      note.textContent = "The explorer needs assets/plotly.min.js beside the report; it is not there.";
      return null;
    }
    if (!blobs.points) {
      note.innerHTML = "The explorer's points (explorer/points.js) are not written: " + spec.how;
      return null;
    }
    const points = decode(blobs.points);
    const pts = { xyz: [points.arrays.xyz1.data, points.arrays.xyz2.data], n: [points.arrays.xyz1.shape[0], points.arrays.xyz2.shape[0]] };
    const stages = spec.stages.map(s => (blobs[s.id] ? decode(blobs[s.id]) : null));
    const missing = spec.stages.filter((s, i) => !stages[i]).map(s => s.id);
    if (missing.length) note.innerHTML = `Not written yet: the explorer data of ${missing.join(", ")}. ` + spec.how;
    const states = stageStates(pts, stages);
    const origin = T => [[0, 0, 0], T ? [T[0][3], T[1][3], T[2][3]] : [0, 0, 0]];
    const ctx = {
      pair: spec.pair, ids: spec.stages.map(s => s.id), labels: spec.stages.map(s => s.label), points, stages, states,
      hover: stages.map(s => (s ? Array.from(s.arrays.magnitude.data, (_, i) => voxelText(s, i)) : null)),
      origins: stages.map(s => origin(s ? s.header.T_1_2 : points.header.T_1_2)),
      magnification: autoMagnification(pts, stages), bounds: bounds(pts), colourBy: "magnitude", selected: null,
      stage: Math.min(initialStage(), stages.length - 1), layers: Object.fromEntries(LAYERS.map(([k]) => [k, true])), ui: {},
    };
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
      box.addEventListener("change", () => { ctx.layers[key] = box.checked; draw(ctx); });
    }
    ctx.ui.budget = control("p", { className: "note budget-drawn" }, root);
    const views = control("div", { className: "explorer-views" }, root);
    for (const view of ["3d", "top"]) {
      const box = control("div", { className: "explorer-view" }, views);
      ctx.ui[view] = control("div", { className: `explorer-plot explorer-${view}` }, box);
      const png = control("button", { type: "button", textContent: `PNG of the ${view === "3d" ? "3-D view" : "top view"}` }, box);
      png.addEventListener("click", () => Plotly.downloadImage(ctx.ui[view], { format: "png", filename: `${ctx.pair}-${ctx.ids[ctx.stage]}-${view}`, scale: 2 }));
    }
    ctx.ui.selected = control("p", { className: "selected-voxel" }, root);
    slider.addEventListener("input", () => {
      ctx.stage = +slider.value;
      history.replaceState(null, "", `#stage=${ctx.stage}`); // a link to this stage of the pair
      draw(ctx);
    });
    colour.addEventListener("change", () => { ctx.colourBy = colour.value; draw(ctx); });
    mag.addEventListener("change", () => { if (+mag.value > 0) { ctx.magnification = +mag.value; draw(ctx); } });
    ctx.ready = draw(ctx).then(() => {
      for (const view of ["3d", "top"])
        ctx.ui[view].on("plotly_click", e => {
          const p = e.points.find(q => q.data.name === "vector tips");
          if (p) { ctx.selected = p.customdata; draw(ctx); }
        });
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
  // Explorers of one group (data-link) share their camera and their stage: lidarfield compare.
  function link(contexts) {
    let syncing = false;
    for (const ctx of contexts) {
      const others = contexts.filter(c => c !== ctx);
      ctx.ui["3d"].on("plotly_relayout", e => {
        // a drag reports scene.camera, a script may set a part of it (scene.camera.eye)
        if (syncing || !Object.keys(e).some(k => k.startsWith("scene.camera"))) return;
        syncing = true;
        const camera = JSON.parse(JSON.stringify(ctx.ui["3d"]._fullLayout.scene.camera));
        Promise.all(others.map(o => Plotly.relayout(o.ui["3d"], { "scene.camera": camera }))).then(() => {
          syncing = false;
        });
      });
      ctx.ui.slider.addEventListener("input", () => {
        for (const o of others) {
          o.ui.slider.value = Math.min(ctx.stage, o.stages.length - 1);
          o.stage = +o.ui.slider.value;
          draw(o);
        }
      });
    }
  }

  document.addEventListener("DOMContentLoaded", () => {
    const groups = {};
    for (const root of document.querySelectorAll(".explorer")) {
      const spec = JSON.parse(root.querySelector("script[type='application/json']").textContent);
      const built = loadData(spec).then(mine => {
        performance.mark("explorer data loaded");
        const ctx = build(root, mine);
        return ctx && ctx.ready.then(() => Object.assign(ctx, { root }));
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
