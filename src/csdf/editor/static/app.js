// csdf live editor: CodeMirror 6 text, WebGL2 sphere-traced preview, parameter sliders.
//
// Flow: text change -> (250 ms debounce) POST /api/compile -> GLSL `sdf`/`sdf_grad`
// and `sdf_albedo` (the surface colour) spliced into the tracer below -> one WebGL2 program. Sliders only call
// gl.uniform1f and redraw (window.csdfEditor.compileCount counts shader compiles).
// The camera follows csdf.Camera.look_at (OpenCV frame: x right, y down, z forward,
// world z up), so a CPU render with the same eye/target/fov shows the same view.
(() => {
  "use strict";

  const CM = window.CM;
  const query = new URLSearchParams(window.location.search);
  const DEBOUNCE_MS = 250;

  // ------------------------------------------------------------------ public state
  const api = {
    ready: false,            // true once the first model is compiled and drawn
    compileCount: 0,         // successful WebGL program builds
    renderCount: 0,          // frames drawn
    requestCount: 0,         // compile requests answered
    lastError: null,         // {line, column, message} of the current error, or null
    params: {},              // current parameter values {name: value}
  };
  window.csdfEditor = api;

  const $ = (id) => document.getElementById(id);
  const statusEl = $("status");
  const canvas = $("view");

  function setStatus(text, kind) {
    statusEl.textContent = text;
    statusEl.className = kind || "";
  }

  // ------------------------------------------------------------------ language mode
  // A small stream tokenizer for the .csdf language (see docs/language.md):
  // keywords, numbers, strings, comments, operators, calls, methods, parameter names.
  const KEYWORDS = new Set(["param", "let", "def", "export", "in"]);
  const T = CM.tags;
  const csdfLanguage = CM.StreamLanguage.define({
    name: "csdf",
    startState: () => ({ expect: null, params: new Set() }),
    copyState: (s) => ({ expect: s.expect, params: new Set(s.params) }),
    token(stream, state) {
      if (stream.eatSpace()) return null;
      if (stream.match(/^#.*/)) return "comment";
      if (stream.match(/^"[^"\n]*"?/) || stream.match(/^'[^'\n]*'?/)) return "string";
      if (stream.match(/^(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?/)) return "number";
      const m = stream.match(/^[A-Za-z_][A-Za-z0-9_]*/);
      if (m) {
        const word = m[0];
        if (KEYWORDS.has(word)) {
          state.expect = word === "param" ? "param" : (word === "let" || word === "def") ? "def" : null;
          return "keyword";
        }
        const expect = state.expect;
        state.expect = null;
        if (expect === "param") { state.params.add(word); return "paramDef"; }
        if (expect === "def") return "definition";
        if (state.params.has(word)) return "paramRef";
        if (stream.match(/^\s*\(/, false)) {
          const before = stream.string.slice(0, stream.start).trimEnd();
          return before.endsWith(".") ? "method" : "func";
        }
        return "variableName";
      }
      if (stream.match(/^[|&~]/)) return "logicOperator";
      if (stream.match(/^[-+*/=]/)) return "operator";
      if (stream.match(/^[()[\],.]/)) return "punctuation";
      stream.next();
      return null;
    },
    tokenTable: {
      paramDef: T.special(T.definition(T.variableName)),
      paramRef: T.special(T.variableName),
      definition: T.definition(T.variableName),
      func: T.function(T.variableName),
      method: T.function(T.propertyName),
      logicOperator: T.logicOperator,
    },
    languageData: { commentTokens: { line: "#" } },
  });
  const highlight = CM.HighlightStyle.define([
    { tag: T.keyword, color: "#c792ea", fontWeight: "600" },
    { tag: T.number, color: "#f78c6c" },
    { tag: T.string, color: "#c3e88d" },
    { tag: T.comment, color: "#6a7585", fontStyle: "italic" },
    { tag: T.special(T.definition(T.variableName)), color: "#ffcb6b", fontWeight: "600" },
    { tag: T.special(T.variableName), color: "#ffcb6b" },
    { tag: T.definition(T.variableName), color: "#82aaff", fontWeight: "600" },
    { tag: T.function(T.variableName), color: "#82aaff" },
    { tag: T.function(T.propertyName), color: "#89ddff" },
    { tag: T.logicOperator, color: "#ff5370", fontWeight: "600" },
    { tag: T.operator, color: "#89ddff" },
  ]);
  const theme = CM.EditorView.theme({
    "&": { backgroundColor: "#171a20", color: "#d8dde5" },
    ".cm-content": { caretColor: "#e0a04a" },
    ".cm-gutters": { backgroundColor: "#171a20", color: "#56606e", border: "none" },
    ".cm-activeLine": { backgroundColor: "#1e232b" },
    ".cm-activeLineGutter": { backgroundColor: "#1e232b" },
    "&.cm-focused .cm-selectionBackground, .cm-selectionBackground": { backgroundColor: "#2f3a4d" },
    "&.cm-focused .cm-cursor": { borderLeftColor: "#e0a04a" },
  }, { dark: true });

  // ------------------------------------------------------------------ editor
  let debounceTimer = null;
  let savedText = null;
  let modelName = "model.csdf";
  let modelPath = null;
  const view = new CM.EditorView({
    parent: $("code"),
    state: CM.EditorState.create({
      doc: "",
      extensions: [
        CM.lineNumbers(), CM.highlightActiveLineGutter(), CM.highlightSpecialChars(),
        CM.history(), CM.drawSelection(), CM.indentOnInput(), CM.bracketMatching(),
        CM.highlightActiveLine(), CM.lintGutter(),
        csdfLanguage, CM.syntaxHighlighting(highlight), theme,
        CM.keymap.of([
          { key: "Mod-s", preventDefault: true, run: () => { save(); return true; } },
          CM.indentWithTab, ...CM.defaultKeymap, ...CM.historyKeymap,
        ]),
        CM.EditorView.updateListener.of((u) => {
          if (!u.docChanged) return;
          updateDirty();
          clearTimeout(debounceTimer);
          debounceTimer = setTimeout(() => compile(view.state.doc.toString()), DEBOUNCE_MS);
        }),
      ],
    }),
  });
  api.view = view;
  api.getText = () => view.state.doc.toString();
  api.setText = (text) => view.dispatch({ changes: { from: 0, to: view.state.doc.length, insert: text } });

  function updateDirty() {
    const el = $("filename");
    el.textContent = modelPath ? modelName : `${modelName} (not saved to a file)`;
    el.classList.toggle("dirty", savedText === null || view.state.doc.toString() !== savedText);
  }

  function showError(err) {
    api.lastError = err;
    const where = err.line ? `line ${err.line}, column ${err.column}: ` : "";
    setStatus(`${where}${err.message}${err.hint ? `\nhint: ${err.hint}` : ""}`, "error");
    const doc = view.state.doc;
    let diagnostics = [];
    if (err.line >= 1 && err.line <= doc.lines) {
      const line = doc.line(err.line);
      const from = Math.min(line.from + Math.max(err.column - 1, 0), line.to);
      const to = Math.min(from + Math.max(err.width || 1, 1), line.to);
      diagnostics = [{ from, to: Math.max(to, from), severity: "error",
                       message: `${where}${err.message}` }];
    }
    view.dispatch(CM.setDiagnostics(view.state, diagnostics));
  }

  function clearError() {
    api.lastError = null;
    view.dispatch(CM.setDiagnostics(view.state, []));
  }

  // ------------------------------------------------------------------ server calls
  async function post(path, body) {
    return fetch(path, {
      method: "POST",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify(body),
    });
  }

  async function errorText(res) {
    try {
      const data = await res.json();
      if (typeof data.error === "string") return data.error;
      if (data.error && data.error.text) return data.error.text;
    } catch (e) { /* not JSON */ }
    return `${res.status} ${res.statusText}`;
  }

  let compileSeq = 0;
  async function compile(text) {
    const seq = ++compileSeq;
    if (new Blob([text]).size > maxBytes) {
      showError({ line: 0, column: 0, message: `the model is over ${maxBytes} bytes` });
      return;
    }
    let res, data;
    try {
      res = await post("/api/compile", { text });
      data = await res.json();
    } catch (e) {
      if (seq === compileSeq) showError({ line: 0, column: 0, message: `server unreachable: ${e}` });
      return;
    }
    if (seq !== compileSeq) return; // a newer edit is on its way
    api.requestCount++;
    if (!data.ok) {
      showError(typeof data.error === "string" ? { line: 0, column: 0, message: data.error } : data.error);
      return;
    }
    if (buildProgram(data)) {
      clearError();
      const i = data.info;
      setStatus(`ok: ${i.instructions} instructions, ${i.params} parameter(s), ${i.exactness}`, "ok");
    }
  }

  function paramValues() {
    return Object.assign({}, api.params);
  }

  function download(blob, name) {
    const url = URL.createObjectURL(blob);
    const a = document.createElement("a");
    a.href = url;
    a.download = name;
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
  }

  async function save() {
    const text = view.state.doc.toString();
    const body = { text };
    if (!modelPath) {
      const name = window.prompt("Save as (a NAME.csdf file in the editor's folder):", "model.csdf");
      if (!name) return;
      body.filename = name;
    }
    setStatus("saving...");
    const res = await post("/api/save", body);
    if (!res.ok) { setStatus(`save failed: ${await errorText(res)}`, "error"); return; }
    const data = await res.json();
    savedText = text;
    modelName = data.name;
    modelPath = data.name;
    updateDirty();
    setStatus(`saved ${data.name} (${data.bytes} bytes)`, "ok");
  }

  async function exportMesh(format) {
    const stem = modelName.replace(/\.csdf$/, "");
    const resolution = parseInt($("resolution").value, 10);
    setStatus(`meshing at resolution ${resolution}...`);
    const res = await post("/api/export/mesh", {
      text: view.state.doc.toString(), format, resolution, params: paramValues() });
    if (!res.ok) { setStatus(`export failed: ${await errorText(res)}`, "error"); return; }
    const blob = await res.blob();
    download(blob, `${stem}.${format}`);
    setStatus(`exported ${stem}.${format} (${blob.size} bytes)`, "ok");
  }

  async function exportShadertoy() {
    const stem = modelName.replace(/\.csdf$/, "");
    const res = await post("/api/export/shadertoy", {
      text: view.state.doc.toString(), params: paramValues() });
    if (!res.ok) { setStatus(`export failed: ${await errorText(res)}`, "error"); return; }
    const text = await res.text();
    download(new Blob([text], { type: "text/plain" }), `${stem}.shadertoy.glsl`);
    try { await navigator.clipboard.writeText(text); } catch (e) { /* no clipboard */ }
    setStatus(`exported ${stem}.shadertoy.glsl (paste into Shadertoy's Image tab)`, "ok");
  }

  $("save").addEventListener("click", save);
  window.addEventListener("beforeunload", (e) => {
    if (savedText !== null && view.state.doc.toString() !== savedText) e.preventDefault();
  });
  $("export-stl").addEventListener("click", () => exportMesh("stl"));
  $("export-obj").addEventListener("click", () => exportMesh("obj"));
  $("export-shadertoy").addEventListener("click", exportShadertoy);

  // ------------------------------------------------------------------ WebGL2
  const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true });
  const VERTEX = `#version 300 es
void main() {
  vec2 v = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(v * 2.0 - 1.0, 0.0, 1.0);
}
`;
  const TRACER = `
uniform vec2 csdf_res;
uniform vec3 csdf_eye;
uniform vec3 csdf_ax;      // camera x (right), world frame
uniform vec3 csdf_ay;      // camera y (down)
uniform vec3 csdf_az;      // camera z (forward)
uniform float csdf_focal;  // pixels
uniform vec3 csdf_lo;      // tracing box
uniform vec3 csdf_hi;
uniform float csdf_step;   // step scale (1 / Lipschitz bound)
uniform float csdf_eps;    // hit tolerance (model units)
uniform int csdf_mode;     // 0 shaded, 1 silhouette mask, 2 normals (0.5 + 0.5 n)
uniform int csdf_slice;    // -1 off, else the axis of the slice plane
uniform float csdf_slice_at;
uniform float csdf_scale;  // diagonal of the box
out vec4 csdf_color;

vec2 csdfBox(vec3 ro, vec3 rd) {
  vec3 inv = 1.0 / (rd + vec3(1e-20));
  vec3 t0 = (csdf_lo - ro) * inv;
  vec3 t1 = (csdf_hi - ro) * inv;
  vec3 a = min(t0, t1);
  vec3 b = max(t0, t1);
  return vec2(max(max(a.x, a.y), max(a.z, 0.0)), min(min(b.x, b.y), b.z));
}

vec3 csdfBackground(vec3 rd) {
  return mix(vec3(0.075, 0.085, 0.10), vec3(0.26, 0.29, 0.34), 0.5 + 0.5 * rd.z);
}

vec3 csdfNormal(vec3 p) {
  vec3 g = sdf_grad(p).yzw;
  float n = length(g);
  if (n > 1e-12) return g / n;
  vec2 e = vec2(1e-4 * csdf_scale, 0.0);
  return normalize(vec3(sdf(p + e.xyy) - sdf(p - e.xyy), sdf(p + e.yxy) - sdf(p - e.yxy),
                        sdf(p + e.yyx) - sdf(p - e.yyx)) + vec3(1e-20));
}

void main() {
  // OpenCV pixel (u, v) = (x - 0.5, H - y - 0.5), principal point at the image centre
  vec2 q = vec2(gl_FragCoord.x - 0.5 * csdf_res.x, 0.5 * csdf_res.y - gl_FragCoord.y) / csdf_focal;
  vec3 rd = normalize(q.x * csdf_ax + q.y * csdf_ay + csdf_az);
  vec3 ro = csdf_eye;
  vec2 span = csdfBox(ro, rd);
  float t = span.x;
  bool hit = false;
  if (span.x < span.y) {
    for (int i = 0; i < 400; i++) {
      float d = sdf(ro + t * rd);
      if (abs(d) < csdf_eps) { hit = true; break; }
      t += max(abs(d) * csdf_step, 0.25 * csdf_eps);
      if (t > span.y) break;
    }
  }
  if (csdf_mode == 1) {
    csdf_color = vec4(vec3(hit ? 1.0 : 0.0), 1.0);
    return;
  }
  if (csdf_mode == 2) {
    csdf_color = vec4(hit ? 0.5 + 0.5 * csdfNormal(ro + t * rd) : vec3(0.0), 1.0);
    return;
  }
  vec3 col = csdfBackground(rd);
  if (hit) {
    vec3 p = ro + t * rd;
    vec3 n = csdfNormal(p);
    if (dot(n, rd) > 0.0) n = -n;
    // key light above and right of the camera, a dim fill from the left, sky ambient
    vec3 l = normalize(-csdf_az + 0.6 * csdf_ax - 0.9 * csdf_ay);
    vec3 lf = normalize(-csdf_az - 0.8 * csdf_ax + 0.2 * csdf_ay);
    float dif = clamp(dot(n, l), 0.0, 1.0);
    float fil = clamp(dot(n, lf), 0.0, 1.0);
    float amb = 0.6 + 0.4 * n.z;
    float spe = pow(clamp(dot(reflect(rd, n), l), 0.0, 1.0), 32.0);
    vec3 base = mix(sdf_albedo(p), 0.5 + 0.5 * n, 0.12);  // the model's colours
    col = base * (0.25 * amb + 0.75 * dif + 0.18 * fil) + 0.15 * spe;
  }
  if (csdf_slice >= 0) {
    float o = ro[csdf_slice];
    float r = rd[csdf_slice];
    float tp = abs(r) > 1e-9 ? (csdf_slice_at - o) / r : -1.0;
    if (tp > 0.0 && (!hit || tp < t)) {
      vec3 p = ro + tp * rd;
      vec3 pc = clamp(p, csdf_lo, csdf_hi);
      if (distance(p, pc) < 1e-6 * csdf_scale + 1e-9) {
        float d = sdf(p);
        float w = d / (0.04 * csdf_scale);
        vec3 c = d < 0.0 ? vec3(0.90, 0.55, 0.25) : vec3(0.30, 0.55, 0.85);
        c *= 0.75 + 0.25 * cos(6.2831853 * w);
        c *= 1.0 - exp(-3.0 * abs(w));
        // the zero isoline, about 1.5 pixels wide (pixel footprint on the plane; no
        // fwidth here: derivatives are undefined in non-uniform control flow)
        float px = tp / (csdf_focal * max(abs(r), 0.15));
        float line = 1.0 - smoothstep(0.0, 1.5 * px, abs(d));
        c = mix(c, vec3(1.0), line);
        col = mix(col, c, 0.85);
      }
    }
  }
  csdf_color = vec4(pow(clamp(col, 0.0, 1.0), vec3(0.4545)), 1.0);
}
`;
  const UNIFORMS = ["csdf_res", "csdf_eye", "csdf_ax", "csdf_ay", "csdf_az", "csdf_focal",
    "csdf_lo", "csdf_hi", "csdf_step", "csdf_eps", "csdf_mode", "csdf_slice",
    "csdf_slice_at", "csdf_scale"];

  let vertexShader = null;
  let current = null; // {program, loc: {}, params: [...], step}
  let bounds = [[-1, -1, -1], [1, 1, 1]];
  let box = null;     // padded tracing box
  let cameraFramed = false;

  function glError(text) {
    const el = $("gl-error");
    el.hidden = !text;
    el.textContent = text || "";
  }

  if (!gl) {
    glError("WebGL2 is not available in this browser: no preview (the text, sliders and exports still work).");
  } else {
    vertexShader = gl.createShader(gl.VERTEX_SHADER);
    gl.shaderSource(vertexShader, VERTEX);
    gl.compileShader(vertexShader);
  }

  function buildProgram(data) {
    updateParams(data.params);
    updateInfo(data.info);
    setBounds(data.bounds);
    if (!gl) { api.ready = true; return true; }
    const source = "#version 300 es\nprecision highp float;\nprecision highp int;\n" + data.glsl + TRACER;
    const fs = gl.createShader(gl.FRAGMENT_SHADER);
    gl.shaderSource(fs, source);
    gl.compileShader(fs);
    const program = gl.createProgram();
    gl.attachShader(program, vertexShader);
    gl.attachShader(program, fs);
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) {
      const log = (gl.getShaderInfoLog(fs) || "") + (gl.getProgramInfoLog(program) || "");
      gl.deleteProgram(program);
      gl.deleteShader(fs);
      showError({ line: 0, column: 0, message: `GPU shader did not compile (previous preview kept): ${log}` });
      return false;
    }
    gl.deleteShader(fs);
    if (current) gl.deleteProgram(current.program);
    const loc = {};
    for (const name of UNIFORMS) loc[name] = gl.getUniformLocation(program, name);
    for (const p of data.params) loc[p.uniform] = gl.getUniformLocation(program, p.uniform);
    current = { program, loc, params: data.params, step: data.step };
    api.compileCount++;
    glError(null);
    gl.useProgram(program);
    for (const p of data.params) gl.uniform1f(loc[p.uniform], api.params[p.name]);
    draw();
    api.ready = true;
    return true;
  }

  function setBounds(b) {
    const valid = Array.isArray(b) && b.length === 2;
    const nb = valid ? b : [[-1.5, -1.5, -1.5], [1.5, 1.5, 1.5]];
    const changed = JSON.stringify(nb) !== JSON.stringify(bounds);
    bounds = nb;
    const diag = Math.hypot(...[0, 1, 2].map((k) => bounds[1][k] - bounds[0][k]));
    const pad = 0.02 * diag + 1e-6;
    box = { lo: bounds[0].map((v) => v - pad), hi: bounds[1].map((v) => v + pad), diag };
    if (!cameraFramed || (changed && !userMovedCamera)) { resetCamera(); cameraFramed = true; }
    updateSliceRange();
  }

  // ------------------------------------------------------------------ camera
  // Orbit camera about `target`: eye = target + dist * (cos el cos az, cos el sin az, sin el).
  const cam = { target: [0, 0, 0], dist: 3, az: 0, el: 0.4, fov: 40 };
  let userMovedCamera = false;

  function resetCamera() {
    const c = [0, 1, 2].map((k) => 0.5 * (bounds[0][k] + bounds[1][k]));
    const radius = 0.5 * box.diag;
    const dir = [1.2, -1.5, 1.0]; // the default view of csdf.render.auto_camera
    const n = Math.hypot(...dir);
    const halfV = (cam.fov * Math.PI / 180) / 2;
    const aspect = canvas.width / Math.max(canvas.height, 1);
    const half = Math.min(halfV, Math.atan(Math.tan(halfV) * aspect));
    cam.target = c;
    cam.dist = Math.max(radius, 1e-3) / Math.sin(half);
    cam.az = Math.atan2(dir[1], dir[0]);
    cam.el = Math.asin(dir[2] / n);
    userMovedCamera = false;
    requestDraw();
  }

  const sub = (a, b) => a.map((v, i) => v - b[i]);
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => { const n = Math.hypot(...a); return a.map((v) => v / n); };

  function cameraFrame() {
    const ce = Math.cos(cam.el);
    const eye = [0, 1, 2].map((k) => cam.target[k] + cam.dist * [ce * Math.cos(cam.az), ce * Math.sin(cam.az), Math.sin(cam.el)][k]);
    const z = norm(sub(cam.target, eye));
    const x = norm(cross(z, [0, 0, 1]));
    const y = cross(z, x);
    const focal = 0.5 * canvas.height / Math.tan((cam.fov * Math.PI / 180) / 2);
    return { eye, x, y, z, focal };
  }

  api.camera = () => {
    const f = cameraFrame();
    return { eye: f.eye, target: cam.target.slice(), fov: cam.fov, width: canvas.width,
             height: canvas.height, focal: f.focal };
  };
  api.setCamera = (c) => { Object.assign(cam, c); userMovedCamera = true; draw(); };

  let drag = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey || e.button === 1 };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x;
    const dy = e.clientY - drag.y;
    drag.x = e.clientX;
    drag.y = e.clientY;
    if (drag.pan) {
      const f = cameraFrame();
      const s = cam.dist * 2 * Math.tan((cam.fov * Math.PI / 180) / 2) / Math.max(canvas.clientHeight, 1);
      cam.target = cam.target.map((v, k) => v - s * (dx * f.x[k] + dy * f.y[k]));
    } else {
      cam.az -= dx * 0.01;
      cam.el = Math.max(-1.55, Math.min(1.55, cam.el + dy * 0.01));
    }
    userMovedCamera = true;
    interact();
    requestDraw();
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    cam.dist *= Math.exp(0.0015 * e.deltaY);
    userMovedCamera = true;
    interact();
    requestDraw();
  }, { passive: false });
  canvas.addEventListener("dblclick", resetCamera);
  $("reset-view").addEventListener("click", resetCamera);

  // ------------------------------------------------------------------ slice plane
  function sliceAxis() { return parseInt($("slice-axis").value, 10); }
  function updateSliceRange() {
    const k = sliceAxis();
    const el = $("slice-at");
    el.min = String(bounds[0][k]);
    el.max = String(bounds[1][k]);
    el.step = String((bounds[1][k] - bounds[0][k]) / 500 || 0.001);
    const v = parseFloat(el.value);
    if (!(v >= bounds[0][k] && v <= bounds[1][k])) el.value = String(0.5 * (bounds[0][k] + bounds[1][k]));
  }
  $("slice-on").addEventListener("change", requestDraw);
  $("slice-axis").addEventListener("change", () => {
    const k = sliceAxis();
    $("slice-at").value = String(0.5 * (bounds[0][k] + bounds[1][k]));
    updateSliceRange();
    requestDraw();
  });
  $("slice-at").addEventListener("input", () => { interact(); requestDraw(); });

  // ------------------------------------------------------------------ drawing
  let pending = false;
  let interacting = false;
  let idleTimer = null;
  function interact() {
    if (query.get("canvas")) return; // fixed size (tests, screenshots)
    clearTimeout(idleTimer);
    if (!interacting) { interacting = true; resize(); }
    idleTimer = setTimeout(() => { interacting = false; resize(); requestDraw(); }, 200);
  }
  function requestDraw() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; draw(); });
  }

  function resize() {
    const fixed = query.get("canvas");
    if (fixed && /^\d+x\d+$/.test(fixed)) {
      const [w, h] = fixed.split("x").map((v) => Math.max(16, Math.min(4096, parseInt(v, 10))));
      canvas.width = w;
      canvas.height = h;
      canvas.classList.add("fixed");
      canvas.style.width = `${w}px`;
      canvas.style.height = `${h}px`;
      return;
    }
    // while the user drags or slides, draw at half resolution (software WebGL and
    // slow GPUs stay interactive), then at full resolution once idle
    const scale = Math.min(window.devicePixelRatio || 1, 1.5) * (interacting ? 0.5 : 1);
    const w = Math.max(16, Math.round(canvas.clientWidth * scale));
    const h = Math.max(16, Math.round(canvas.clientHeight * scale));
    if (w !== canvas.width || h !== canvas.height) {
      canvas.width = w;
      canvas.height = h;
      requestDraw();
    }
  }
  new ResizeObserver(resize).observe($("canvas-wrap"));
  resize();

  const MODES = { shaded: 0, mask: 1, normals: 2 };
  function draw(mode) {
    if (!gl || !current) return;
    const L = current.loc;
    const f = cameraFrame();
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.useProgram(current.program);
    gl.uniform2f(L.csdf_res, canvas.width, canvas.height);
    gl.uniform3fv(L.csdf_eye, f.eye);
    gl.uniform3fv(L.csdf_ax, f.x);
    gl.uniform3fv(L.csdf_ay, f.y);
    gl.uniform3fv(L.csdf_az, f.z);
    gl.uniform1f(L.csdf_focal, f.focal);
    gl.uniform3fv(L.csdf_lo, box.lo);
    gl.uniform3fv(L.csdf_hi, box.hi);
    gl.uniform1f(L.csdf_step, current.step);
    gl.uniform1f(L.csdf_eps, 2e-5 * box.diag);
    gl.uniform1f(L.csdf_scale, box.diag);
    gl.uniform1i(L.csdf_mode, MODES[mode] || 0);
    gl.uniform1i(L.csdf_slice, $("slice-on").checked && !MODES[mode] ? sliceAxis() : -1);
    gl.uniform1f(L.csdf_slice_at, parseFloat($("slice-at").value));
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    api.renderCount++;
  }

  // A PNG data URL of the preview: 'shaded' (what the page shows), 'mask' (white where
  // a ray hits the surface) or 'normals' (0.5 + 0.5 * the world-frame unit normal).
  api.snapshot = (mode) => {
    draw(mode);
    const url = canvas.toDataURL("image/png");
    if (MODES[mode]) draw();
    return url;
  };
  api.draw = () => draw();

  // ------------------------------------------------------------------ parameters
  function sliderRange(p) {
    let lo = p.lo;
    let hi = p.hi;
    const span = Math.max(1, Math.abs(p.default));
    if (!Number.isFinite(lo)) lo = p.default - span;
    if (!Number.isFinite(hi)) hi = p.default + span;
    if (!(hi > lo)) { lo -= 0.5; hi += 0.5; }
    return [lo, hi];
  }

  const fmt = (v) => (Math.abs(v) >= 1000 || (Math.abs(v) < 1e-3 && v !== 0)) ? v.toExponential(2) : v.toPrecision(4).replace(/\.?0+$/, "");
  let paramKey = "";
  function updateParams(params) {
    const key = JSON.stringify(params.map((p) => [p.name, p.uniform, p.default, p.lo, p.hi]));
    if (key === paramKey) return;
    const old = api.params;
    const oldSpec = {};
    for (const p of (current ? current.params : [])) oldSpec[p.name] = p;
    paramKey = key;
    const box_ = $("params");
    box_.textContent = "";
    api.params = {};
    if (params.length === 0) {
      box_.innerHTML = '<div class="empty">no parameters (declare one with <code>param name = value in [lo, hi]</code>)</div>';
      return;
    }
    for (const p of params) {
      const prev = oldSpec[p.name];
      const same = prev && prev.default === p.default && prev.lo === p.lo && prev.hi === p.hi;
      const value = same && p.name in old ? old[p.name] : p.default;
      api.params[p.name] = value;
      const [lo, hi] = sliderRange(p);
      const row = document.createElement("div");
      row.className = "param";
      const id = `param-${p.uniform}`;
      const label = document.createElement("label");
      label.htmlFor = id;
      label.textContent = p.name;
      label.title = `${p.name}: default ${p.default}, range [${p.lo}, ${p.hi}]`;
      const input = document.createElement("input");
      input.type = "range";
      input.id = id;
      input.dataset.name = p.name;
      input.min = String(lo);
      input.max = String(hi);
      input.step = String(10 ** Math.floor(Math.log10((hi - lo) / 500)));
      input.value = String(value);
      const out = document.createElement("output");
      out.htmlFor = id;
      out.textContent = fmt(value);
      input.addEventListener("input", () => {
        const v = parseFloat(input.value);
        api.params[p.name] = v;
        out.textContent = fmt(v);
        if (gl && current) {
          gl.useProgram(current.program);
          gl.uniform1f(current.loc[p.uniform], v);
          interact();
          requestDraw();
        }
      });
      input.addEventListener("dblclick", () => {
        input.value = String(p.default);
        input.dispatchEvent(new Event("input"));
      });
      row.append(label, input, out);
      box_.appendChild(row);
    }
  }

  // ------------------------------------------------------------------ info panel
  function updateInfo(info) {
    const el = $("info");
    const lip = info.lipschitz === null ? "unbounded" : fmt(info.lipschitz);
    const rows = Object.entries(info.levels).map(([level, c]) =>
      `<tr><td>${level}</td><td>${c.bytes}</td><td>${c.add}</td><td>${c.mul}</td><td>${c.div}</td><td>${c.call}</td><td>${c.branch}</td></tr>`).join("");
    const b = info.bounds ? `${info.bounds[0].map(fmt).join(", ")} .. ${info.bounds[1].map(fmt).join(", ")}` : "unknown";
    el.innerHTML =
      `<div class="facts"><b>${info.instructions}</b> instructions, <b>${info.params}</b> parameter(s)<br>` +
      `exactness: <b class="exactness"></b>, Lipschitz <b>${lip}</b><br>bounds: ${b}</div>` +
      "<table><tr><th>level</th><th>bytes</th><th>add</th><th>mul</th><th>div</th><th>call</th><th>branch</th></tr>" +
      rows + "</table>";
    el.querySelector(".exactness").textContent = info.exactness;
  }

  // ------------------------------------------------------------------ start
  let maxBytes = 256 * 1024;
  (async () => {
    try {
      const res = await fetch("/api/model");
      if (!res.ok) throw new Error(await errorText(res));
      const data = await res.json();
      maxBytes = data.max_bytes;
      modelName = data.name;
      modelPath = data.path;
      savedText = data.path ? data.text : null;
      document.title = `${data.name} - csdf editor`;
      clearTimeout(debounceTimer);
      view.dispatch({ changes: { from: 0, to: view.state.doc.length, insert: data.text } });
      clearTimeout(debounceTimer);
      updateDirty();
      await compile(data.text);
    } catch (e) {
      setStatus(`could not load the model: ${e}`, "error");
    }
  })();
})();
