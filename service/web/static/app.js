// flexopt web page: calls the same /v1 API as every client. No build step, no CDN: plotly.js is served by
// the package (static/vendor/plotly, MIT). State for tests and the curious: window.flexopt.
"use strict";

const $ = (id) => document.getElementById(id);
// every string from the server or a file goes through textContent or esc() before it reaches markup (plotly's
// titles and hover templates are markup too): a scene named <img src=x onerror=...> is text, never an element
const esc = (t) => String(t).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);
// plotly's titles, names and hover templates: tags are its only markup and it decodes &amp; &lt; &gt; (not &quot;)
const escPlot = (t) => String(t).replace(/[&<>]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;" })[c]);
const state = { scene: null, fileScene: null, curve: null, shapes: null, templates: [], diagnosis: null, job: null,
  topoJob: null, topoThumbs: {}, paretoJob: null };
window.flexopt = state;

// ------------------------------------------------------------------------------------------------- API
// A failed request throws an Error whose .problem is the server's problem details (RFC 9457: errors[].loc names
// the field) and .status the HTTP status.
async function api(method, path, body) {
  const headers = { "Accept": "application/json" };
  const key = localStorage.getItem("flexopt-api-key");
  if (key) headers["X-API-Key"] = key;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const r = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  const text = await r.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch (e) { data = { detail: text }; }
  if (!r.ok) {
    let msg = (data && (data.detail || data.title)) || `HTTP ${r.status}`;
    if (data && data.errors && data.errors.length) // one line per field (the detail repeats the first)
      msg = data.errors.map((e) => `${(e.loc || []).filter((x) => x !== "body").join(".")}: ${e.msg}`).join("\n");
    if (r.status === 401) {
      const k = prompt("This server needs an API key:");
      if (k) { localStorage.setItem("flexopt-api-key", k); return api(method, path, body); }
    }
    const err = new Error(msg);
    err.problem = data;
    err.status = r.status;
    throw err;
  }
  return data;
}

function status(msg, error = false) {
  const el = $("status");
  el.textContent = msg;
  el.className = "status" + (error ? " error" : "");
}

async function busy(label, fn) {
  status(label + " ...");
  const t0 = performance.now();
  try {
    const out = await fn();
    status(`${label}: done in ${((performance.now() - t0) / 1000).toFixed(1)} s`);
    return out;
  } catch (e) {
    status(`${label} failed: ${e.message}`, true);
    throw e;
  }
}

// --------------------------------------------------------------------------------------------- units
// A number shown with its unit and a readable prefix (210 GPa, 0.3 mm, 50 mm, 0.1 kg), in a form the server reads back
// with pint (template parameters accept '0.3 mm'; the page sends what is typed and the server converts it).
const PREFIXED = { // [unit, factor to SI, smallest |value| in SI shown in it]: lengths in mm from 10 um to 1 m
  m: [["µm", 1e-6, 0], ["mm", 1e-3, 1e-5], ["m", 1, 1]],
  Pa: [["Pa", 1, 0], ["kPa", 1e3, 1e3], ["MPa", 1e6, 1e5], ["GPa", 1e9, 1e9]],
  kg: [["mg", 1e-6, 0], ["g", 1e-3, 1e-4], ["kg", 1, 0.1]], N: [["mN", 1e-3, 0], ["N", 1, 0.1], ["kN", 1e3, 1e3]],
  "N m": [["mN m", 1e-3, 0], ["N m", 1, 0.1]], Hz: [["Hz", 1, 0], ["kHz", 1e3, 1e4]],
};

function trimmed(v, digits) { // 0.30000000000000004 -> 0.3; 6.164e-5, not 0.00006164
  const x = parseFloat((+v).toPrecision(digits));
  return x !== 0 && (Math.abs(x) < 1e-3 || Math.abs(x) >= 1e7) ? x.toExponential().replace("e+", "e") : String(x);
}

function quantity(v, unit, digits = 4) {
  if (v === null || v === undefined || !Number.isFinite(+v)) return v === null || v === undefined ? "" : String(v);
  if (!unit) return trimmed(v, digits);
  const scales = PREFIXED[unit];
  if (!scales || +v === 0) return `${trimmed(v, digits)} ${unit}`;
  let pick = scales[0];
  for (const sc of scales) if (Math.abs(v) >= sc[2] * (1 - 1e-9)) pick = sc;
  return `${trimmed(v / pick[1], digits)} ${pick[0]}`;
}

function templateUnits(name) { // parameter -> SI unit (null for counts, words and ratios) of a template
  const t = state.templates.find((x) => x.name === name);
  return Object.fromEntries(t ? t.parameters.map((p) => [p.name, p.unit || null]) : []);
}

// ------------------------------------------------------------------------------------- field errors
// A 422's problem details name the field (errors[].loc); its message goes beside that field.
function fieldFor(loc) {
  const l = (loc || [])[0] === "body" ? loc.slice(1) : (loc || []);
  if (l[0] === "parameters" && l.length > 1)
    return [...$("params").querySelectorAll("input")].find((i) => i.dataset.name === String(l[1])) || null;
  if (l[0] === "tolerance") return $("tolerance");
  if (l[0] === "method") return $("method");
  return null;
}

function clearFieldErrors() {
  for (const d of document.querySelectorAll(".field-error")) d.remove();
  for (const i of document.querySelectorAll("[aria-invalid]")) i.removeAttribute("aria-invalid");
}

function showFieldErrors(err) {
  let shown = 0;
  for (const e of (err && err.problem && err.problem.errors) || []) {
    const inp = fieldFor(e.loc);
    if (!inp) continue;
    inp.setAttribute("aria-invalid", "true");
    const d = document.createElement("div");
    d.className = "field-error";
    d.setAttribute("data-testid", `error-${inp.dataset.name || inp.id}`);
    d.textContent = e.msg;
    inp.closest("label").after(d);
    shown++;
  }
  return shown;
}

// -------------------------------------------------------------------------------------------- design
function renderParams(info) {
  const box = $("params");
  box.innerHTML = "";
  for (const p of info.parameters) {
    const lab = document.createElement("label");
    const shown = p.type === "number" ? quantity(p.default, p.unit, 12) : String(p.default);
    lab.title = `${p.name}: ${p.bounds} (default ${shown})` + (p.unit ? `; a plain number is in ${p.unit}` : "");
    const span = document.createElement("span");
    span.textContent = p.name;
    const inp = document.createElement("input");
    inp.dataset.name = p.name;
    inp.dataset.type = p.type;
    inp.dataset.default = shown;
    inp.type = "text"; // a number with its unit ('0.3 mm'), converted by the server as the CLI's --set does
    inp.spellcheck = false;
    if (p.unit) inp.placeholder = `e.g. ${quantity(p.default, p.unit)}`;
    inp.value = shown;
    lab.append(span, inp);
    box.append(lab);
  }
}

function parameters() { // the changed fields as typed: the server reads numbers and units and names a bad field
  const out = {};
  for (const inp of $("params").querySelectorAll("input")) {
    const v = inp.value.trim();
    if (v !== inp.dataset.default) out[inp.dataset.name] = v;
  }
  return out;
}

async function currentScene() {
  if (state.fileScene) return state.fileScene;
  const name = $("template").value;
  return api("POST", `/v1/templates/${encodeURIComponent(name)}/scene`, { parameters: parameters() });
}

function mm(v) { return `${(v * 1e3).toPrecision(3)} mm`; }

function tolerance() { // a number when it reads as one; else the text, for the server to name the field
  const v = $("tolerance").value.trim();
  return v !== "" && Number.isFinite(Number(v)) ? Number(v) : v;
}

function designSummary(scene) {
  const pos = Object.fromEntries(scene.nodes.map((n) => [n.name, n.position]));
  const seen = new Map();
  for (const e of scene.elements) {
    const [p, q] = e.nodes;
    const L = Math.hypot(...pos[q].map((v, i) => v - pos[p][i]));
    let key = `L ${mm(L)}`;
    if (e.section && e.section.kind === "rectangular") key += `, w ${mm(e.section.width)}, t ${mm(e.section.thickness)}`;
    seen.set(key, (seen.get(key) || []).concat([e.name]));
  }
  return [...seen].map(([k, v]) => (v.length > 1 ? `${v.length}x (${k})` : `${v[0]}: ${k}`)).join("; ");
}

// --------------------------------------------------------------------------------------------- curve
async function computeCurve() {
  clearFieldErrors();
  const name = state.fileScene ? (state.fileScene.name || "scene file") : $("template").value;
  try {
    return await busy(`curve of ${name} (${$("method").value})`, async () => {
      const scene = await currentScene();
      const body = { scene, method: $("method").value, tolerance: tolerance() };
      const curve = await api("POST", "/v1/frequency-curve", body);
      state.scene = scene;
      state.curve = curve;
      $("curve-note").textContent = "";
      drawCurve(curve, scene);
      return curve;
    });
  } catch (e) {
    const marked = showFieldErrors(e);
    clearResults(marked ? `no curve: ${marked} field(s) marked in the design panel need a change` : `no curve: ${e.message}`);
    throw e;
  }
}

// A failed request leaves no result of an earlier design on the page as if it were this one's.
function clearResults(why) {
  state.curve = null;
  state.shapes = null;
  state.scene = null;
  Plotly.purge($("curve"));
  $("curve-note").textContent = why;
  $("warnings").innerHTML = "";
  shapeViewer.stop();
  Plotly.purge($("shape"));
  $("mode-list").innerHTML = "";
  $("shape-title").textContent = "";
  $("scale-note").textContent = "";
}

function drawCurve(c, scene) {
  const traces = [];
  const unit = escPlot(c.stroke_unit);
  const i0 = c.stroke.reduce((b, s, i) => (Math.abs(s) < Math.abs(c.stroke[b]) ? i : b), 0);
  const k = c.modes_hz.length ? c.modes_hz[0].length : 0;
  for (let j = 0; j < k; j++) {
    const lab = c.mode_labels.length ? c.mode_labels[i0][j] : "";
    traces.push({ x: c.stroke, y: c.modes_hz.map((r) => r[j]), name: `mode ${j + 1} (${escPlot(lab)})`, mode: "lines",
      line: { width: 1.2, dash: lab === "parasitic" ? "solid" : lab === "intended" ? "dash" : "dot" },
      hovertemplate: `mode ${j + 1} (${escPlot(lab)})<br>%{x:.4g} ${unit}: %{y:.5g} Hz<extra></extra>` });
  }
  traces.push({ x: c.stroke, y: c.parasitic_hz, name: "first parasitic", mode: "lines+markers",
    line: { width: 4, color: "#c0392b" }, marker: { size: 5, color: "#c0392b" },
    hovertemplate: `first parasitic<br>%{x:.4g} ${unit}: %{y:.5g} Hz<br>click: structure and modes<extra></extra>` });
  let peak = 0;
  for (const [m, vm] of Object.entries(c.max_von_mises)) {
    const allow = c.allowable_stress[m];
    const u = vm.map((v) => (v === null ? null : v / allow));
    for (const v of u) if (v !== null && v > peak) peak = v;
    traces.push({ x: c.stroke, y: u, name: `${escPlot(m)}: von Mises / allowable`, yaxis: "y2", mode: "lines", line: { width: 1.5 },
      hovertemplate: `${escPlot(m)}<br>%{x:.4g} ${unit}: %{y:.3f} of the allowable (${escPlot(quantity(allow, "Pa"))})<extra></extra>` });
  }
  traces.push({ x: [c.stroke[0], c.stroke[c.stroke.length - 1]], y: [1, 1], yaxis: "y2", name: "allowable stress",
    mode: "lines", line: { color: "red", dash: "dash", width: 1.5 }, hoverinfo: "skip" });
  const par = c.parasitic_hz.filter((v) => v !== null);
  const worst = par.length ? Math.min(...par) : null;
  const title = `${escPlot(c.scene)} (${escPlot(c.method)}${c.mesh_error != null ? `, mesh error ${(100 * c.mesh_error).toFixed(2)} %` : ""})` +
    (worst !== null ? `: worst first parasitic ${worst.toPrecision(4)} Hz` : "") +
    (scene ? `<br><span style="font-size:11px">${escPlot(designSummary(scene))}</span>` : "");
  const layout = {
    title: { text: title, font: { size: 14 } }, margin: { t: 60, r: 10, l: 70, b: 45 },
    xaxis: { title: { text: `stroke [${unit}]` }, anchor: "y2" },
    yaxis: { title: { text: "natural frequency [Hz]" }, domain: [0.34, 1], type: $("logf").checked ? "log" : "linear" },
    yaxis2: { title: { text: "stress / allowable [-]" }, domain: [0, 0.25], range: [0, Math.max(1.1, 1.1 * peak)] },
    legend: { font: { size: 11 } }, hovermode: "closest",
  };
  Plotly.newPlot("curve", traces, layout, { responsive: true, displaylogo: false });
  $("curve").on("plotly_click", (ev) => {
    const p = ev.points && ev.points[0];
    if (p) loadModes(p.x).catch(() => {});
  });
  const ul = $("warnings");
  ul.innerHTML = "";
  for (const w of c.warnings || []) {
    const li = document.createElement("li");
    li.textContent = `[${w.kind}] ${w.message}`;
    ul.append(li);
  }
  for (const f of c.failures || []) {
    const li = document.createElement("li");
    li.textContent = `[truncated] ${f.message}`;
    ul.append(li);
  }
}

// ------------------------------------------------------------------------------------------ 3D views
function rotmat(r) { // Rodrigues: rotation vector -> matrix (row-major 3x3)
  const th = Math.hypot(r[0], r[1], r[2]);
  if (th < 1e-14) return [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
  const [x, y, z] = r.map((v) => v / th), c = Math.cos(th), s = Math.sin(th), C = 1 - c;
  return [[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
          [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
          [z * x * C - y * s, z * y * C + x * s, c + z * z * C]];
}
const mul = (R, v) => [0, 1, 2].map((i) => R[i][0] * v[0] + R[i][1] * v[1] + R[i][2] * v[2]);
const matmul = (A, B) => [0, 1, 2].map((i) => [0, 1, 2].map((j) => A[i][0] * B[0][j] + A[i][1] * B[1][j] + A[i][2] * B[2][j]));
const add = (a, b, s = 1) => [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];

function extent(geo) {
  const P = Object.values(geo.nodes);
  let e = 0;
  for (let k = 0; k < 3; k++) e = Math.max(e, Math.max(...P.map((p) => p[k])) - Math.min(...P.map((p) => p[k])));
  return e || 1e-3;
}

function modeScale(geo, mode, fraction) {
  let half = 0;
  for (const m of Object.values(geo.members)) half = Math.max(half, (m.width || 0) / 2);
  let peak = 0, prot = 0;
  for (const n of Object.keys(geo.nodes)) {
    peak = Math.max(peak, Math.hypot(...mode.translation[n]));
    prot = Math.max(prot, Math.hypot(...mode.rotation[n]));
  }
  return fraction * extent(geo) / Math.max(peak + half * prot, 1e-300);
}

// positions and rotations of the deflected state moved by a * mode
function moved(geo, mode, a) {
  const pos = {}, rot = {};
  for (const [n, p] of Object.entries(geo.nodes)) {
    pos[n] = mode ? add(p, mode.translation[n], a) : p;
    const R = rotmat(geo.orientations[n]);
    rot[n] = mode ? matmul(rotmat(mode.rotation[n].map((v) => a * v)), R) : R;
  }
  return { pos, rot };
}

function structureTraces(geo, mode, a, style) {
  const { pos, rot } = moved(geo, mode, a);
  const traces = [];
  const S = 1e3; // drawn in mm
  for (const [name, m] of Object.entries(geo.members)) {
    const chain = m.nodes.filter((n) => n in pos);
    const colourValue = style.memberValue ? style.memberValue[name] : undefined;
    if (m.width && m.y_axis) {
      const x = [], y = [], z = [], I = [], J = [], K = [];
      chain.forEach((n, i) => {
        const d = mul(rot[n], m.y_axis).map((v) => (v * m.width) / 2);
        for (const s of [-1, 1]) { const q = add(pos[n], d, s); x.push(q[0] * S); y.push(q[1] * S); z.push(q[2] * S); }
        if (i > 0) { const b = 2 * (i - 1); I.push(b, b + 1); J.push(b + 2, b + 2); K.push(b + 1, b + 3); }
      });
      const t = { type: "mesh3d", x, y, z, i: I, j: J, k: K, name: escPlot(name), opacity: style.opacity, flatshading: true,
        hovertemplate: `${escPlot(name)}<extra></extra>`, showscale: false };
      if (colourValue !== undefined) {
        Object.assign(t, { intensity: x.map(() => colourValue), colorscale: "RdBu", cmin: -1, cmax: 1 });
        if (style.showscale && !style.scaleShown) {
          t.showscale = true; style.scaleShown = true;
          t.colorbar = { title: { text: "self-stress<br>(normalised)" }, len: 0.6 };
        }
      } else t.color = style.color;
      traces.push(t);
    } else {
      let color = style.color;
      if (colourValue !== undefined) {
        const v = Math.max(-1, Math.min(1, colourValue));
        color = v >= 0 ? `rgb(${178 + 77 * (1 - v)},${24 + 200 * (1 - v)},${43 + 190 * (1 - v)})`
                       : `rgb(${33 + 200 * (1 + v)},${102 + 120 * (1 + v)},${172 + 60 * (1 + v)})`;
      }
      traces.push({ type: "scatter3d", mode: "lines", name: escPlot(name), x: chain.map((n) => pos[n][0] * S),
        y: chain.map((n) => pos[n][1] * S), z: chain.map((n) => pos[n][2] * S),
        line: { width: 6, color }, opacity: style.opacity, hovertemplate: `${escPlot(name)}<extra></extra>` });
    }
  }
  for (const [name, b] of Object.entries(geo.bodies || {})) {
    let R = rotmat(b.orientation);
    let c = add(b.position, mul(R, b.center_offset));
    if (mode && b.nodes.length) {
      const n0 = b.nodes[0], psi = mode.rotation[n0];
      const r = add(c, geo.nodes[n0], -1);
      c = add(c, add(mode.translation[n0], cross(psi, r)), a);
      R = matmul(rotmat(psi.map((v) => a * v)), R);
    }
    const x = [], y = [], z = [];
    for (const i of [-1, 1]) for (const j of [-1, 1]) for (const k of [-1, 1]) {
      const q = add(c, mul(R, [i * b.size[0] / 2, j * b.size[1] / 2, k * b.size[2] / 2]));
      x.push(q[0] * S); y.push(q[1] * S); z.push(q[2] * S);
    }
    traces.push({ type: "mesh3d", x, y, z, alphahull: 0, color: "#34495e", opacity: 0.18 * style.opacity / 0.9,
      name: escPlot(name), hovertemplate: `body ${escPlot(name)}<extra></extra>` });
  }
  return traces;
}

// The leaves' face normals (thickness directions) in the drawn state: a leaf seen along its own plane is a line.
function leafNormals(geo) {
  const out = [];
  for (const m of Object.values(geo.members)) {
    const chain = m.nodes.filter((n) => n in geo.nodes);
    if (!m.width || !m.y_axis || chain.length < 2) continue;
    const p = geo.nodes[chain[0]], q = geo.nodes[chain[chain.length - 1]];
    const y = mul(rotmat(geo.orientations[chain[0]]), m.y_axis);
    const n = cross(add(q, p, -1), y), len = Math.hypot(...n);
    if (len > 0) out.push(n.map((v) => v / len));
  }
  return out;
}

// A camera that shows the whole structure from an oblique view: of the directions 20-40 deg above the x-y plane
// that see every leaf's face at least 20 deg from edge-on (else the best any sees), the nearest to a standard
// front-right view; at a distance proportional to the diagonal of the scene's aspect box (the axes' ranges span
// the whole oscillation), its factor set on screenshots so that the box clears the view's edges with a margin
// (tests/test_web.py checks the pivot's pixels).
function obliqueCamera(geo, aspect) {
  const normals = leafNormals(geo);
  const preferred = [0.6, -0.7, 0.4], pn = Math.hypot(...preferred);
  let best = null;
  for (let el = 20; el <= 40; el += 10) {
    for (let az = 0; az < 360; az += 7.5) {
      const e = (el * Math.PI) / 180, a = (az * Math.PI) / 180;
      const d = [Math.cos(e) * Math.cos(a), Math.cos(e) * Math.sin(a), Math.sin(e)];
      const face = normals.length ? Math.min(...normals.map((n) => Math.abs(n[0] * d[0] + n[1] * d[1] + n[2] * d[2]))) : 1;
      const near = (d[0] * preferred[0] + d[1] * preferred[1] + d[2] * preferred[2]) / pn;
      const score = Math.min(face, 0.35) + 1e-3 * near; // every face at >= 20 deg from edge-on, then the preferred side
      if (!best || score > best.score) best = { score, d, face };
    }
  }
  const radius = Math.hypot(...aspect) / 2;
  const dist = (1.1 * radius) / Math.sin(Math.PI / 8);
  return { eye: { x: dist * best.d[0], y: dist * best.d[1], z: dist * best.d[2] }, center: { x: 0, y: 0, z: 0 },
           up: { x: 0, y: 0, z: 1 } };
}

class Viewer {
  constructor(div) { this.div = div; this.timer = null; this.geo = null; this.mode = null; this.extra = {}; }
  show(geo, mode, extra = {}) {
    this.stop();
    this.geo = geo; this.mode = mode; this.extra = extra;
    this.limits();
    this.frame(mode ? this.amplitude() : 0, true);
    if (mode) this.animate();
  }
  amplitude() { return modeScale(this.geo, this.mode, parseFloat($("amp").value)); }
  limits() { // fixed axes over the whole oscillation (largest amplitude of the slider), equal scales
    const a = this.mode ? modeScale(this.geo, this.mode, parseFloat($("amp").max)) : 0;
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const s of this.mode ? [-a, 0, a] : [0]) {
      for (const t of structureTraces(this.geo, this.mode, s, { color: "#000", opacity: 1 })) {
        ["x", "y", "z"].forEach((k, i) => { for (const v of t[k]) { lo[i] = Math.min(lo[i], v); hi[i] = Math.max(hi[i], v); } });
      }
    }
    const span = Math.max(...hi.map((h, i) => h - lo[i]), 1e-9);
    const half = hi.map((h, i) => Math.max((h - lo[i]) / 2, 0.08 * span) * 1.05);
    const c = hi.map((h, i) => (h + lo[i]) / 2);
    const m = Math.max(...half);
    this.range = c.map((v, i) => [v - half[i], v + half[i]]);
    this.aspect = { x: half[0] / m, y: half[1] / m, z: half[2] / m };
    this.camera = obliqueCamera(this.geo, [this.aspect.x, this.aspect.y, this.aspect.z]);
  }
  frame(a, fresh = false) {
    const base = structureTraces(this.geo, null, 0, { color: "#95a5a6", opacity: this.mode ? 0.3 : 0.9,
      memberValue: this.extra.memberValue, showscale: !!this.extra.memberValue });
    const traces = this.mode ? base.concat(structureTraces(this.geo, this.mode, a, { color: "#e67e22", opacity: 0.9 })) : base;
    const layout = { margin: { t: 10, l: 0, r: 0, b: 0 }, showlegend: false, uirevision: "keep",
      scene: { aspectmode: "manual", aspectratio: this.aspect,
               xaxis: { title: { text: "x [mm]" }, range: this.range[0] }, yaxis: { title: { text: "y [mm]" }, range: this.range[1] },
               zaxis: { title: { text: "z [mm]" }, range: this.range[2] }, camera: this.camera } };
    if (fresh || !this.div.data) Plotly.newPlot(this.div, traces, layout, { displaylogo: false, responsive: true });
    else Plotly.react(this.div, traces, layout);
  }
  animate() {
    const t0 = performance.now();
    const step = () => {
      const a = this.amplitude() * Math.sin((2 * Math.PI * (performance.now() - t0)) / 1600);
      this.frame(a);
      this.timer = setTimeout(() => requestAnimationFrame(step), 60);
    };
    this.timer = setTimeout(step, 60);
  }
  stop() { if (this.timer) clearTimeout(this.timer); this.timer = null; }
}

const shapeViewer = new Viewer($("shape"));
let diagViewer = null;

async function loadModes(stroke) {
  const scene = state.scene || (await currentScene());
  const d = await busy(`modes at stroke ${(+stroke).toPrecision(4)}`, () => api("POST", "/v1/modes", { scene, at_stroke: stroke }));
  state.shapes = d;
  $("shape-title").textContent = `${d.scene} at stroke ${d.stroke.toPrecision(4)} ${d.stroke_unit}: ` +
    `drive reaction ${d.drive_reaction === null ? "n/a" : quantity(d.drive_reaction, d.stroke_kind === "rotation" ? "N m" : "N")}`;
  const list = $("mode-list");
  list.innerHTML = "";
  const deflected = document.createElement("button");
  deflected.textContent = "deflected state only";
  deflected.onclick = () => { select(deflected); shapeViewer.show(d, null); $("scale-note").textContent = ""; };
  list.append(deflected);
  const select = (btn) => { for (const b of list.querySelectorAll("button")) b.classList.remove("active"); btn.classList.add("active"); };
  let first = null;
  d.modes.forEach((m, i) => {
    const b = document.createElement("button");
    b.dataset.testid = `mode-${i + 1}`;
    b.setAttribute("data-testid", `mode-${i + 1}`);
    b.textContent = `mode ${i + 1}: ${m.hz.toPrecision(5)} Hz (${m.label})`;
    b.onclick = () => {
      select(b);
      shapeViewer.show(d, m);
      const a = shapeViewer.amplitude();
      const shown = parseFloat($("amp").value) * extent(d) * 1e3;
      $("scale-note").textContent = `Mode ${i + 1} drawn at scale ${a.toPrecision(3)} (mass-normalised shape; largest ` +
        `displacement shown, plate edges included, ${shown.toPrecision(3)} mm). Grey: the deflected state.`;
    };
    list.append(b);
    if (first === null && m.label === "parasitic") first = b;
  });
  const st = document.createElement("div");
  st.className = "note";
  st.textContent = Object.entries(d.stress).map(([k, v]) => v.utilisation === null ? "" :
    `${k}: ${quantity(v.von_mises, "Pa")} = ${(100 * v.utilisation).toFixed(1)} % of the allowable`).filter(Boolean).join("; ");
  list.append(st);
  for (const w of d.warnings) {
    const p = document.createElement("div");
    p.className = "error";
    p.textContent = `[${w.kind}] ${w.message}`;
    list.append(p);
  }
  (first || deflected).click();
  return d;
}

// ---------------------------------------------------------------------------------------- diagnosis
function sceneGeometry(scene) { // the reference configuration in the shapes wire form
  const pos = Object.fromEntries(scene.nodes.map((n) => [n.name, n.position]));
  const nodes = { ...pos }, members = {}, bodies = {};
  for (const e of scene.elements) {
    const [p, q] = e.nodes, n = e.segments || 1, chain = [p];
    for (let i = 1; i < n; i++) { nodes[`${e.name}#${i}`] = pos[p].map((v, k) => v + ((pos[q][k] - v) * i) / n); chain.push(`${e.name}#${i}`); }
    chain.push(q);
    let y = null;
    if ((e.kind || "beam") === "beam" && e.y_axis) {
      const L = Math.hypot(...pos[q].map((v, k) => v - pos[p][k]));
      const t = pos[q].map((v, k) => (v - pos[p][k]) / L);
      const dot = e.y_axis.reduce((s, v, k) => s + v * t[k], 0);
      y = e.y_axis.map((v, k) => v - dot * t[k]);
      const ny = Math.hypot(...y); y = y.map((v) => v / ny);
    }
    members[e.name] = { nodes: chain, width: e.section && e.section.kind === "rectangular" ? e.section.width : null, y_axis: y };
  }
  const geo = { nodes, members, bodies, orientations: Object.fromEntries(Object.keys(nodes).map((n) => [n, [0, 0, 0]])) };
  const ext = extent(geo);
  for (const b of scene.bodies || []) {
    const pts = b.nodes.map((n) => pos[n]).concat([b.center_of_mass]);
    const lo = [0, 1, 2].map((k) => Math.min(...pts.map((p) => p[k]))), hi = [0, 1, 2].map((k) => Math.max(...pts.map((p) => p[k])));
    bodies[b.name] = { nodes: b.nodes, position: b.center_of_mass, orientation: [0, 0, 0],
      size: [0, 1, 2].map((k) => Math.max(hi[k] - lo[k], 0.06 * ext)),
      center_offset: [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2 - b.center_of_mass[k]) };
  }
  return geo;
}

function freeMotion(scene, geo, motion, Lc) { // diagnosis kinematic mode -> nodal translation/rotation
  const owner = {}, com = {};
  for (const b of scene.bodies || []) { com[b.name] = b.center_of_mass; for (const n of b.nodes) owner[n] = b.name; }
  const translation = {}, rotation = {};
  for (const [n, p] of Object.entries(geo.nodes)) {
    const m = owner[n] || n, v = motion[m];
    if (!v) { translation[n] = [0, 0, 0]; rotation[n] = [0, 0, 0]; continue; }
    const u = (v.translation || [0, 0, 0]).map((x) => Lc * x), psi = v.rotation || [0, 0, 0];
    const r = com[m] ? add(p, com[m], -1) : [0, 0, 0];
    translation[n] = add(u, cross(psi, r));
    rotation[n] = psi;
  }
  return { translation, rotation };
}

function fmtMotion(motion) {
  return Object.entries(motion).map(([m, v]) => {
    const t = (v.translation || []).map((x, k) => (Math.abs(x) > 1e-3 ? `${"xyz"[k]} ${x.toFixed(3)}` : "")).filter(Boolean);
    const r = (v.rotation || []).map((x, k) => (Math.abs(x) > 1e-3 ? `r${"xyz"[k]} ${x.toFixed(3)}` : "")).filter(Boolean);
    return t.length || r.length ? `${m}: ${t.concat(r).join(", ")}` : "";
  }).filter(Boolean).join("; ");
}

async function runDiagnosis() {
  clearFieldErrors();
  let scene, d;
  try {
    [scene, d] = await busy(`diagnosis of ${state.fileScene ? (state.fileScene.name || "scene file") : $("template").value}`,
      async () => { const sc = await currentScene(); return [sc, await api("POST", "/v1/diagnosis", { scene: sc })]; });
  } catch (e) {
    showFieldErrors(e);
    $("diagnosis").textContent = `no diagnosis: ${e.message}`;
    throw e;
  }
  state.scene = scene;
  state.diagnosis = d;
  const box = $("diagnosis");
  box.innerHTML = "";
  const h = document.createElement("p");
  h.innerHTML = `<b>${esc(d.classification)}</b>: D<sub>cc</sub> ${+d.m} x ${+d.n}, rank ${+d.rank}, ` +
    `${d.kinematic_modes.length} free motion(s), ${d.static_modes.length} self-stress(es); ` +
    `condition number ${d.condition_number === null ? "n/a" : (+d.condition_number).toPrecision(3)}` +
    (d.almost_singular ? " <span class='error'>(almost singular)</span>" : "");
  box.append(h);
  const stress = {};
  if (d.static_modes.length) {
    let smax = 0;
    for (const [el, comps] of Object.entries(d.static_modes[0])) {
      const member = el.split("[")[0].split("#")[0];
      const v = Object.values(comps).reduce((a, b) => (Math.abs(b) > Math.abs(a) ? b : a), 0);
      if (Math.abs(v) > Math.abs(stress[member] || 0)) stress[member] = v;
      smax = Math.max(smax, Math.abs(v));
    }
    for (const k of Object.keys(stress)) stress[k] /= smax || 1;
  }
  const row = document.createElement("div");
  row.className = "row";
  const div = document.createElement("div");
  div.className = "plot3d";
  div.setAttribute("data-testid", "diagnosis-3d");
  const side = document.createElement("div");
  side.className = "side";
  row.append(div, side);
  box.append(row);
  const geo = sceneGeometry(scene);
  diagViewer = new Viewer(div);
  const extra = Object.keys(stress).length ? { memberValue: stress } : {};
  const still = document.createElement("button");
  still.textContent = Object.keys(stress).length ? "first self-stress (colours)" : "structure";
  still.onclick = () => diagViewer.show(geo, null, extra);
  side.append(still);
  d.kinematic_modes.forEach((motion, i) => {
    const b = document.createElement("button");
    b.textContent = `free motion ${i + 1}`;
    b.title = fmtMotion(motion);
    b.onclick = () => diagViewer.show(geo, freeMotion(scene, geo, motion, d.characteristic_length), extra);
    side.append(b);
    const p = document.createElement("div");
    p.className = "note";
    p.textContent = `free motion ${i + 1} (translations in L_c = ${mm(d.characteristic_length)} per unit, rotations in rad per unit): ${fmtMotion(motion)}`;
    side.append(p);
  });
  d.static_modes.forEach((s, i) => {
    const p = document.createElement("div");
    p.className = "note";
    p.textContent = `self-stress ${i + 1}: ` + Object.entries(s).map(([el, c]) =>
      `${el} ${Object.entries(c).map(([k, v]) => `${k} ${v.toFixed(3)}`).join(" ")}`).join("; ");
    side.append(p);
  });
  if (d.release_candidates.length) {
    const p = document.createElement("div");
    p.className = "note";
    p.textContent = "to release (one of each set): " + d.release_candidates.map((r) => r.join(", ")).join(" | ");
    side.append(p);
  }
  (d.kinematic_modes.length ? side.querySelectorAll("button")[1] : still).click();
  return d;
}

// ------------------------------------------------------------------------------------- optimisation
const DEFAULT_PROBLEM = {
  families: [{ template: "cross-spring-pivot", design: { thickness: [1e-4, 4e-4], width: [0.01, 0.04] } }],
  stroke: 20, samples: 5, modes: 1, starts: 2, max_iterations: 30, refine_rounds: 1, verify_points: 31,
};

async function submitOptimisation() {
  let spec;
  try { spec = JSON.parse($("problem").value); } catch (e) { status(`problem is not valid JSON: ${e.message}`, true); return; }
  const job = await busy("submitting optimisation", () => api("POST", "/v1/optimisations", spec));
  state.job = job;
  $("cancel-opt").disabled = false;
  pollJob(job.id);
}

// one design parameter with its unit, and whether the optimum sits on a bound of the design box
function designText(template, design, activeBounds, bounds) {
  const units = templateUnits(template);
  return Object.entries(design || {}).map(([k, v]) => {
    const side = (activeBounds || {})[k];
    const box = bounds && bounds[k] ? bounds[k][side === "lower" ? 0 : 1] : null;
    return `${k} ${quantity(v, units[k])}` + (side ? ` (at its ${side} bound${box == null ? "" : " " + quantity(box, units[k])})` : "");
  }).join(", ");
}

function cell(tr, text, cls) {
  const td = document.createElement("td");
  td.textContent = text;
  if (cls) td.className = cls;
  tr.append(td);
  return td;
}

function renderJob(job) {
  const p = job.progress || {}, done = p.done || 0, total = p.total || 1;
  const box = $("opt-progress");
  box.innerHTML = "job <span></span>: <b></b>, <span></span><div class=\"bar\"><div></div></div>";
  const [id, st, count] = box.querySelectorAll("span, b");
  id.textContent = job.id;
  st.textContent = job.status;
  count.textContent = `${done} of ${total} cases`;
  box.querySelector(".bar > div").style.width = `${(100 * done) / total}%`;
  if (job.error) {
    const e = document.createElement("div");
    e.className = "error";
    e.textContent = job.error;
    box.append(e);
  }
  const fams = (job.result && job.result.families) || []; // the box searched (a raised thickness floor included)
  const boundsOf = (template) => ((fams.find((f) => f.template === template && f.best) || {}).best || {}).bounds;
  const rows = (job.result && job.result.ranking) ? job.result.ranking.map((r, i) => ({ rank: i + 1, family: r.template,
    template: r.template, worst: r.worst_hz, zero: r.zero_stroke_hz, design: r.design, active: r.active_bounds,
    bounds: boundsOf(r.template) }))
    : (job.partial || []).filter((q) => q.verified && q.verified.worst_hz != null)
        .sort((a, b) => b.verified.worst_hz - a.verified.worst_hz)
        .map((q, i) => ({ rank: i + 1, family: `${q.family} (start ${q.start})`, template: q.family, worst: q.verified.worst_hz,
          zero: q.verified.zero_stroke_hz, design: q.design, active: (q.optimality || {}).active_bounds, bounds: q.bounds }));
  const t = $("ranking");
  t.innerHTML = `<tr><th>rank</th><th class="l">family</th><th>worst first parasitic [Hz]</th><th>at stroke 0 [Hz]</th><th class="l">design</th></tr>`;
  for (const r of rows) {
    const tr = document.createElement("tr");
    cell(tr, String(r.rank));
    cell(tr, r.family, "l");
    cell(tr, (+r.worst).toPrecision(5));
    cell(tr, r.zero == null ? "" : (+r.zero).toPrecision(5));
    cell(tr, designText(r.template, r.design, r.active, r.bounds), "l design");
    t.append(tr);
  }
  const ul = $("opt-warnings");
  ul.innerHTML = "";
  for (const w of (job.result && job.result.warnings) || []) {
    const li = document.createElement("li");
    li.textContent = `[${w.kind}] ${w.message}`;
    ul.append(li);
  }
}

async function pollJob(id) {
  const job = await api("GET", `/v1/optimisations/${id}`);
  state.job = job;
  renderJob(job);
  if (["queued", "running", "cancelling"].includes(job.status)) setTimeout(() => pollJob(id), 1000);
  else $("cancel-opt").disabled = true;
}

// ---------------------------------------------------------------------------------- topology search
const SVG_NS = "http://www.w3.org/2000/svg";

function thumbnail(scene, size = 96) { // a small oblique top view (x right, y up, z towards the viewer): leaves and bodies
  const pos = Object.fromEntries(scene.nodes.map((n) => [n.name, n.position]));
  const P = (p) => [p[0] + 0.45 * p[2], p[1] + 0.3 * p[2]];
  const pts = Object.values(pos).map(P).concat((scene.bodies || []).map((b) => P(b.center_of_mass)));
  const lo = [0, 1].map((k) => Math.min(...pts.map((p) => p[k]))), hi = [0, 1].map((k) => Math.max(...pts.map((p) => p[k])));
  const span = Math.max(hi[0] - lo[0], hi[1] - lo[1], 1e-9), pad = 8, sc = (size - 2 * pad) / span;
  const XY = (p) => { const q = P(p); return [pad + (q[0] - lo[0]) * sc + ((size - 2 * pad) - (hi[0] - lo[0]) * sc) / 2,
    size - pad - (q[1] - lo[1]) * sc - ((size - 2 * pad) - (hi[1] - lo[1]) * sc) / 2]; };
  const parts = [];
  for (const b of scene.bodies || []) { // a body: spokes from its centre of mass to its nodes
    const c = XY(b.center_of_mass), col = b.name === "rotor" || b.name === "slider" ? "#e67e22" : "#7f8c8d";
    for (const n of b.nodes) { const q = XY(pos[n]); parts.push(`<line x1="${c[0]}" y1="${c[1]}" x2="${q[0]}" y2="${q[1]}" stroke="${col}" stroke-width="3" stroke-linecap="round" opacity="0.7"/>`); }
    parts.push(`<circle cx="${c[0]}" cy="${c[1]}" r="3.5" fill="${col}"><title>${esc(b.name)}</title></circle>`);
  }
  for (const e of scene.elements) { // a leaf or wire
    const [p, q] = e.nodes.map((n) => XY(pos[n]));
    parts.push(`<line class="leaf" x1="${p[0]}" y1="${p[1]}" x2="${q[0]}" y2="${q[1]}" stroke="#2471a3" stroke-width="2"><title>${esc(e.name)}</title></line>`);
  }
  for (const s of scene.supports || []) { // ground
    if (!s.node || !pos[s.node]) continue;
    const q = XY(pos[s.node]);
    parts.push(`<rect x="${q[0] - 3}" y="${q[1] - 3}" width="6" height="6" fill="#222"/>`);
  }
  return `<svg xmlns="${SVG_NS}" class="thumb" width="${size}" height="${size}" viewBox="0 0 ${size} ${size}">${parts.join("")}</svg>`;
}

async function submitTopology() {
  let spec;
  try { spec = JSON.parse($("topo-spec").value); } catch (e) { status(`topology spec is not valid JSON: ${e.message}`, true); return; }
  const job = await busy("submitting topology search", () => api("POST", "/v1/topology-searches", spec));
  state.topoJob = job;
  state.topoThumbs = {};
  $("cancel-topo").disabled = false;
  pollTopology(job.id);
}

function topoRows(result) { // the ranking first (best first), then every other candidate as generated
  const c = result.candidates, order = Object.fromEntries(result.ranking.map((t, i) => [t, i]));
  return c.slice().sort((a, b) => (order[a.topology] ?? 1e9) - (order[b.topology] ?? 1e9));
}

const fmtHz = (v) => (v == null ? "" : (+v).toPrecision(4));

// a search's counts as its job status carries them (service.jobs: progress.counts), in the order of the schedule
const TOPO_COUNTS = [["generated", "generated"], ["screened", "screened"], ["passed", "passed the filter"],
  ["first_pass", "first pass"], ["optimised", "optimised"], ["verified", "verified"]];

// The search's progress as the job's status carries it: the phase and its cases, the counts, the best so far
// (descriptor and worst case); every server string through esc().
function renderTopoProgress(job) {
  const p = job.progress || {}, done = +p.done || 0, total = +p.total || 0;
  const phase = p.phase != null ? String(p.phase) : (job.status === "running" ? "generating and screening" : "");
  const cases = total ? `${done} of ${total} cases` : "";
  let html = `search ${esc(job.id)}: <b data-testid="topo-status">${esc(job.status)}</b>` +
    (phase ? `, phase <b data-testid="topo-phase">${esc(phase)}</b>` : "") +
    (cases ? `: <span data-testid="topo-cases">${esc(cases)}</span>` : "") + `<div class="bar"><div></div></div>`;
  const c = p.counts || {}, shown = TOPO_COUNTS.filter(([k]) => c[k] != null);
  if (shown.length) html += `<div class="note" data-testid="topo-counts">` +
    shown.map(([k, label]) => `${esc(label)} <b data-count="${esc(k)}">${esc(c[k])}</b>`).join(", ") + `</div>`;
  if (p.best) html += `<div data-testid="topo-best">best so far: <code>${esc(p.best.topology)}</code>, worst case ` +
    `<b>${esc(fmtHz(p.best.worst_hz))} Hz</b>${p.best.phase ? ` (${esc(p.best.phase)})` : ""}</div>`;
  if (job.error) html += `<div class="error">${esc(job.error)}</div>`;
  $("topo-progress").innerHTML = html;
  $("topo-progress").querySelector(".bar > div").style.width = `${total ? Math.min(100, (100 * done) / total) : 0}%`;
}

function renderTopology(job) {
  renderTopoProgress(job);
  const t = $("topo-ranking");
  if (!job.result) { t.innerHTML = ""; return; }
  const r = job.result, n = r.counts;
  $("topo-progress").insertAdjacentHTML("beforeend", `<div class="note" data-testid="topo-summary">${+n.generated} generated, ` +
    `${+n.rejected} rejected, ${+n.untraceable} untraceable, ${n.pruned != null ? `${+n.pruned} pruned, ` : ""}` +
    `${+n.optimised} optimised, ${+n.failed} failed; best: ${r.best ? esc(r.best.topology) : "none"}</div>`);
  const rows = topoRows(r);
  // the ranking is by the refined worst case (the verification mesh that meets the spec's tolerance) when there is one
  t.innerHTML = `<tr><th>rank</th><th>topology</th><th class="l">descriptor</th><th class="l">family</th><th>dof</th><th>overconstraints</th>` +
    `<th class="l">status / reason</th><th>worst-case [Hz]</th><th>at stroke 0 [Hz]</th><th>refined worst case [Hz]</th></tr>` +
    rows.map((c, i) => { const rank = r.ranking.indexOf(c.topology);
      return `<tr data-topology="${esc(c.topology)}"><td>${rank >= 0 ? rank + 1 : ""}</td><td class="thumbcell" id="thumb-${i}"></td>` +
        `<td class="l"><code>${esc(c.topology)}</code></td><td class="l">${esc(c.family_form || c.family || "-")}</td><td>${esc(c.dof ?? "")}</td>` +
        `<td>${esc(c.overconstraints ?? "")}</td><td class="l reason">${esc(c.status)}${c.reason ? ": " + esc(c.reason) : ""}</td>` +
        `<td>${fmtHz(c.worst_case_hz)}</td><td>${fmtHz(c.zero_stroke_hz)}</td><td>${esc(fmtHz((c.refined || {}).worst_hz))}</td></tr>`; }).join("");
  drawThumbnails(rows, r.spec.motion).catch((e) => status(`thumbnails: ${e.message}`, true));
}

async function drawThumbnails(rows, motion) { // the optimised design's scene, else the template's default sizes
  const tpl = motion === "translation" ? "wire-guide-topology" : "topology-hinge";
  for (const [i, c] of rows.slice(0, 80).entries()) {
    let scene = c.scene || state.topoThumbs[c.topology];
    if (!scene) {
      try { scene = await api("POST", `/v1/templates/${tpl}/scene`, { parameters: { topology: c.topology } }); }
      catch (e) { $(`thumb-${i}`).textContent = "-"; continue; }
      state.topoThumbs[c.topology] = scene;
    }
    const cell = $(`thumb-${i}`);
    if (cell) cell.innerHTML = thumbnail(scene);
  }
}

async function pollTopology(id) {
  const job = await api("GET", `/v1/topology-searches/${id}`);
  state.topoJob = job;
  renderTopology(job);
  if (["queued", "running", "cancelling"].includes(job.status)) setTimeout(() => pollTopology(id), 1000);
  else $("cancel-topo").disabled = true;
}

async function initTopology() {
  $("topo-spec").value = JSON.stringify(await api("GET", "/v1/topology-searches/example"), null, 1);
  $("topology").onclick = () => submitTopology().catch(() => {});
  $("cancel-topo").onclick = async () => { if (state.topoJob) renderTopology(await api("DELETE", `/v1/topology-searches/${state.topoJob.id}`)); };
}

// ------------------------------------------------------------------------------------------- Pareto front
// A front's job carries its phase (optima, levels, strokes, check, check verification), {done, total} of it and a
// summary of every finished case (status, worst case, and a front point's kind and verified drive stiffness or
// stroke): while it runs the page draws the front so far from them; the front itself comes with the result.
const FRONT_KINDS = ["max_frequency", "min_drive", "epsilon", "stroke"];

// The front so far: the finished cases that are verified optimal front points (not the check's designs), x their
// drive stiffness (or stroke), and the non-dominated ones among them (the least drive stiffness, or the longest
// stroke, for a worst case) in order of x.
function partialFront(job) {
  const cases = (job.partial || []).filter((q) => FRONT_KINDS.includes(q.kind) && q.status === "optimal" &&
    q.worst_hz != null && (q.kind === "stroke" ? q.stroke : q.drive_stiffness) != null);
  const key = cases.some((q) => q.kind === "stroke") ? "stroke" : "drive_stiffness";
  const pts = cases.map((q) => ({ x: +q[key], y: +q.worst_hz, q }));
  const byBetterX = pts.slice().sort((a, b) => (key === "stroke" ? b.x - a.x : a.x - b.x));
  const front = [];
  let top = -Infinity;
  for (const p of byBetterX) if (p.y > top) { front.push(p); top = p.y; }
  return { key, points: pts, front: front.sort((a, b) => a.x - b.x) };
}

function renderPartialFront(job) {
  const { key, points, front } = partialFront(job);
  if (!points.length) { Plotly.purge($("pareto-plot")); return; }
  const xlabel = key === "stroke" ? "stroke (half range)" : "drive stiffness (peak drive / stroke)";
  const others = points.filter((p) => !front.includes(p));
  const traces = [{ x: front.map((p) => p.x), y: front.map((p) => p.y), name: "front so far (verified)", mode: "lines+markers",
    line: { color: "#c0392b", dash: "dot" }, marker: { size: 8 }, hovertemplate: `%{x:.4g}: %{y:.4g} Hz<extra></extra>` }];
  if (others.length) traces.push({ x: others.map((p) => p.x), y: others.map((p) => p.y), name: "other finished starts",
    mode: "markers", marker: { color: "#999" }, hovertemplate: `%{x:.4g}: %{y:.4g} Hz<extra></extra>` });
  Plotly.react("pareto-plot", traces, { title: { text: "Pareto front so far", font: { size: 14 } },
    margin: { t: 40, r: 10, l: 70, b: 45 }, xaxis: { title: { text: xlabel } },
    yaxis: { title: { text: "worst-case first parasitic [Hz]" } }, hovermode: "closest" }, { responsive: true, displaylogo: false });
}

function renderPareto(job) {
  const p = job.progress || {}, done = +p.done || 0, total = +p.total || 0;
  const optima = partialFront(job).points; // the check's designs are not verified optima: not counted here
  const best = optima.length ? Math.max(...optima.map((q) => q.y)) : null;
  $("pareto-progress").innerHTML = `front ${esc(job.id)}: <b data-testid="pareto-status">${esc(job.status)}</b>` +
    (p.phase != null ? `, phase <b data-testid="pareto-phase">${esc(p.phase)}</b>` : "") +
    (total ? `, <span data-testid="pareto-cases">${esc(`${done} of ${total} cases of this phase`)}</span>` : "") +
    `<div class="bar"><div></div></div>` +
    ((job.partial || []).length ? `<div class="note" data-testid="pareto-finished">${esc(`${job.partial.length} cases finished`)}` +
      (best != null ? `, highest verified worst case so far <b>${esc(fmtHz(best))} Hz</b>` : "") + `</div>` : "") +
    (job.error ? `<div class="error">${esc(job.error)}</div>` : "");
  $("pareto-progress").querySelector(".bar > div").style.width = `${total ? Math.min(100, (100 * done) / total) : 0}%`;
  const r = job.result, t = $("pareto-points"), ul = $("pareto-warnings");
  ul.innerHTML = "";
  if (!r) { t.innerHTML = ""; renderPartialFront(job); return; }
  const key = r.against === "stroke" ? "stroke" : "drive_stiffness";
  const unit = key === "stroke" ? (r.stroke_unit || "") : (r.drive_stiffness_unit || "");
  const xlabel = key === "stroke" ? `stroke (half range) [${unit}]` : `drive stiffness (peak drive / stroke) [${unit}]`;
  const pts = (r.points || []).slice().sort((a, b) => a[key] - b[key]);
  const designOf = (q) => designText(r.template, q.design); // each parameter with its unit (the template's)
  const traces = [{ x: pts.map((q) => q[key]), y: pts.map((q) => q.worst_hz), name: "front (verified)", mode: "lines+markers",
    line: { color: "#c0392b" }, marker: { size: 8 }, text: pts.map((q) => escPlot(designOf(q))),
    hovertemplate: `%{x:.4g} ${escPlot(unit)}: %{y:.4g} Hz<br>%{text}<extra></extra>` }];
  const chk = r.check || {};
  if (chk.points && chk.points.length) traces.push({ x: chk.points.map((q) => q.drive_stiffness), y: chk.points.map((q) => q.worst_hz),
    name: `NSGA-II check (${+chk.evaluations || 0} curves): ${chk.passed ? "passed" : "FAILED"}`, mode: "markers",
    marker: { symbol: "x", color: "#999" }, hovertemplate: `%{x:.4g}: %{y:.4g} Hz<extra>NSGA-II</extra>` });
  Plotly.newPlot("pareto-plot", traces, { title: { text: `${escPlot(r.template)}: Pareto front`, font: { size: 14 } },
    margin: { t: 40, r: 10, l: 70, b: 45 }, xaxis: { title: { text: escPlot(xlabel) } },
    yaxis: { title: { text: "worst-case first parasitic [Hz]" } }, hovermode: "closest" }, { responsive: true, displaylogo: false });
  t.innerHTML = `<tr><th>point</th><th>${esc(xlabel)}</th><th>worst case [Hz]</th><th>at stroke 0 [Hz]</th><th>stress ratio</th>` +
    `<th class="l">design</th></tr>` + pts.map((q, i) => `<tr><td>${i + 1}</td><td>${esc(trimmed(q[key], 4))}</td>` +
    `<td>${esc(fmtHz(q.worst_hz))}</td><td>${esc(fmtHz(q.zero_stroke_hz))}</td>` +
    `<td>${q.stress_ratio == null ? "-" : esc((+q.stress_ratio).toFixed(3))}</td><td class="l design">${esc(designOf(q))}</td></tr>`).join("");
  for (const w of r.warnings || []) {
    const li = document.createElement("li");
    li.textContent = `[${w.kind}] ${w.message}`;
    ul.append(li);
  }
}

async function submitPareto() {
  let spec;
  try { spec = JSON.parse($("pareto-spec").value); } catch (e) { status(`Pareto spec is not valid JSON: ${e.message}`, true); return; }
  const job = await busy("submitting Pareto front", () => api("POST", "/v1/pareto-fronts", spec));
  state.paretoJob = job;
  $("cancel-pareto").disabled = false;
  pollPareto(job.id);
}

async function pollPareto(id) {
  const job = await api("GET", `/v1/pareto-fronts/${id}`);
  state.paretoJob = job;
  renderPareto(job);
  if (["queued", "running", "cancelling"].includes(job.status)) setTimeout(() => pollPareto(id), 1000);
  else $("cancel-pareto").disabled = true;
}

async function initPareto() {
  $("pareto-spec").value = JSON.stringify(await api("GET", "/v1/pareto-fronts/example"), null, 1);
  $("pareto").onclick = () => submitPareto().catch(() => {});
  $("cancel-pareto").onclick = async () => { if (state.paretoJob) renderPareto(await api("DELETE", `/v1/pareto-fronts/${state.paretoJob.id}`)); };
}

// ------------------------------------------------------------------------------------------- start
async function init() {
  const [health, templates] = await Promise.all([api("GET", "/health"), api("GET", "/v1/templates")]);
  $("version").textContent = `v${health.version}`;
  $("method").replaceChildren(...health.methods.map((m) => new Option(m, m)));
  state.templates = templates;
  const sel = $("template");
  sel.replaceChildren(...templates.map((t) => new Option(t.name, t.name)));
  const q = new URLSearchParams(location.search);
  const want = q.get("template") || "leaf-spring";
  if (templates.some((t) => t.name === want)) sel.value = want;
  const render = () => renderParams(templates.find((t) => t.name === sel.value));
  sel.onchange = () => { state.fileScene = null; $("scene-note").textContent = ""; render(); };
  render();
  if (q.get("method") && health.methods.includes(q.get("method"))) $("method").value = q.get("method");
  $("scene-file").onchange = async (ev) => {
    const f = ev.target.files[0];
    if (!f) return;
    if (/\.dat$/i.test(f.name)) { // a SPACAR model: the server maps it (every unmappable line is an error with its number)
      try {
        const imp = await api("POST", "/v1/scenes/import", { text: await f.text(), name: f.name.replace(/\.dat$/i, "") });
        state.fileScene = imp.scene;
        $("scene-note").textContent = `using SPACAR model ${f.name} (node numbering ${imp.numbering}; SPACAR degrees of ` +
          `freedom ${imp.spacar_dof}${imp.notes.length ? "; " + imp.notes.join("; ") : ""})`;
      } catch (e) { status(`${f.name}: ${e.message}`, true); }
      return;
    }
    try { state.fileScene = JSON.parse(await f.text()); $("scene-note").textContent = `using scene file ${f.name} (${state.fileScene.name || "unnamed"})`; }
    catch (e) { status(`${f.name} is not valid JSON: ${e.message}`, true); }
  };
  $("compute").onclick = () => computeCurve().catch(() => {});
  $("statespace").onclick = () => runStateSpace().catch(() => {});
  $("diagnose").onclick = () => runDiagnosis().catch(() => {});
  $("logf").onchange = () => { if (state.curve) drawCurve(state.curve, state.scene); };
  $("amp").oninput = () => {};
  $("stop").onclick = () => { shapeViewer.stop(); if (diagViewer) diagViewer.stop(); };
  $("problem").value = JSON.stringify(DEFAULT_PROBLEM, null, 1);
  $("optimise").onclick = () => submitOptimisation().catch(() => {});
  $("cancel-opt").onclick = async () => { if (state.job) renderJob(await api("DELETE", `/v1/optimisations/${state.job.id}`)); };
  await initTopology();
  await initPareto();
  if (q.get("template")) await computeCurve();
}

// ------------------------------------------------------------------------------------- state space
async function runStateSpace() {
  const f = [];
  for (let k = 0; k <= 120; ++k) f.push(10 ** (-1 + k * 5 / 120)); // 0.1 Hz .. 10 kHz, log spaced
  const num = (id) => { const v = $(id).value.trim(); return v !== "" && Number.isFinite(Number(v)) ? Number(v) : v; };
  let ss;
  try {
    ss = await busy("state-space model", async () => {
      const scene = await currentScene();
      return api("POST", "/v1/state-space", { scene, at_stroke: num("ss-stroke"), inputs: [$("ss-input").value.trim()],
        outputs: [$("ss-output").value.trim()], damping: num("ss-damping"), frequencies_hz: f });
    });
  } catch (e) {
    $("ss-note").textContent = `no model: ${e.message}`;
    throw e;
  }
  state.stateSpace = ss;
  const mag = ss.bode.magnitude.map((m) => m[0][0]);
  const phase = ss.bode.phase_deg.map((p) => p[0][0]);
  $("ss-note").textContent = `${ss.A.length} states (${ss.frequencies_hz.length} modes, damping ${ss.damping}); ` +
    `static gain ${(+ss.static_gain[0][0]).toPrecision(4)}; lowest modes ` +
    ss.frequencies_hz.slice(0, 4).map((h) => `${(+h).toPrecision(4)} Hz`).join(", ");
  Plotly.newPlot("bode", [
    { x: ss.bode.frequency_hz, y: mag, name: "magnitude", type: "scatter", mode: "lines" },
    { x: ss.bode.frequency_hz, y: phase, name: "phase [deg]", type: "scatter", mode: "lines", yaxis: "y2" },
  ], { margin: { t: 10 }, xaxis: { type: "log", title: "frequency [Hz]" }, yaxis: { type: "log", title: `|${ss.outputs[0]} / ${ss.inputs[0]}|` },
    yaxis2: { overlaying: "y", side: "right", title: "phase [deg]" } }, { responsive: true, displaylogo: false });
  return ss;
}

init().catch((e) => status(`could not start: ${e.message}`, true));
