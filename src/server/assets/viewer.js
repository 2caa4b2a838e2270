// rbfsurf viewer: upload a point file, follow the job by server-sent events, then show the
// returned binary glTF with plain WebGL (no libraries but the vendored meshoptimizer decoder, works
// offline). The GLB reader handles the files rbfsurf writes, plain or compact (quantized +
// meshopt-compressed): one indexed triangle primitive with POSITION (+ NORMAL, + COLOR_0 vertex
// colours, linear RGB in the file, shown sRGB-encoded; orange when the mesh has none) per mesh; a
// morph's GLB (one mesh per frame node, a STEP animation) is played frame by frame. Two finished
// jobs can be composed (union, intersection, difference, blend) or morphed through the volume API.
"use strict";

const $ = (id) => document.getElementById(id);
let chosen = null;

// ---------- upload and job tracking ----------
function mediaType(name) {
  const ext = name.split(".").pop().toLowerCase();
  return { ply: "application/ply", csv: "text/csv", obj: "model/obj", xyz: "text/plain",
           pts: "text/plain", txt: "text/plain", las: "application/vnd.las",
           laz: "application/vnd.laszip" }[ext] || "application/octet-stream";
}

function setStatus(text, isError) {
  $("status").textContent = text;
  $("status").className = isError ? "error" : "";
}

function choose(file) {
  chosen = file;
  $("filename").textContent = file ? `${file.name} (${(file.size / 1024).toFixed(0)} KiB)` : "";
  $("go").disabled = !file;
  if (file) setStatus("Ready: press Reconstruct.");
}

function queryString() {
  const q = new URLSearchParams();
  for (const k of ["resolution", "neighbours", "kernel", "carrier", "solver", "boundary",
                   "min-component", "border-reach", "smoothing", "outlier-std-ratio", "color",
                   "lods"]) {
    const v = $(k).value.trim();
    if (v) q.set(k, v);
  }
  return q.toString();
}

async function submit() {
  if (!chosen) return;
  $("go").disabled = true;
  $("stats").innerHTML = "";
  $("links").innerHTML = "";
  $("bar").value = 0;
  setStatus("Uploading…");
  const headers = { "Content-Type": mediaType(chosen.name) };
  const token = $("token").value.trim();
  if (token) headers["Authorization"] = "Bearer " + token;
  try {
    const r = await fetch("/v1/reconstructions?" + queryString(), { method: "POST", headers, body: chosen });
    const body = await r.json();
    if (!r.ok) throw new Error(body.error ? `${body.error.code}: ${body.error.message}` : `HTTP ${r.status}`);
    location.hash = "job=" + body.id;
    follow(body.id);
  } catch (e) {
    setStatus("Upload failed: " + e.message, true);
    $("go").disabled = false;
  }
}

function follow(id) {
  setStatus("Queued…");
  const es = new EventSource(`/v1/reconstructions/${id}/events`);
  const show = (ev) => {
    const v = JSON.parse(ev.data);
    $("bar").value = v.progress;
    if (v.status === "queued") setStatus("Queued…");
    else if (v.status === "running") setStatus(`Running: ${v.stage || "…"} ${(100 * v.stage_progress).toFixed(0)}%`);
    return v;
  };
  es.addEventListener("progress", show);
  es.addEventListener("done", (ev) => {
    es.close();
    const v = show(ev);
    finished(v);
  });
  es.onerror = () => {
    es.close();
    // The stream can drop (proxies, restarts): fall back to one blocking status request.
    fetch(`/v1/reconstructions/${id}?wait=600`).then((r) => r.json()).then((v) => {
      if (v.error && !v.id) setStatus(`${v.error.code}: ${v.error.message}`, true);
      else finished(v);
    });
  };
}

async function finished(v) {
  $("go").disabled = !chosen;
  refreshJobs();
  if (v.status !== "succeeded") {
    const err = v.error ? `${v.error.code}: ${v.error.message}` : v.status;
    setStatus(`Job ${v.status}: ${err}`, true);
    return;
  }
  setStatus("Downloading mesh…");
  const job = await (await fetch(`/v1/reconstructions/${v.id}`)).json();
  showStats(job.report);
  const base = `/v1/reconstructions/${v.id}`;
  $("links").innerHTML = `Download: <a href="${base}/mesh.glb" download>GLB</a> · ` +
    `<a href="${base}/mesh.ply" download>PLY</a> · <a href="${base}/mesh.obj" download>OBJ</a> · ` +
    `<a href="${base}/report" target="_blank">report</a>`;
  try {
    // Levels of detail (when the job asked for them), coarse to fine, then the full mesh; all in
    // the frame of the first file shown, the camera kept between them.
    const levels = [];
    for (let k = 1; k <= 8; k++) {
      const r = await fetch(`${base}/lods/${k}`, { method: "HEAD" });
      if (!r.ok) break;
      levels.unshift(k);
    }
    let origin = null;
    for (const k of levels) {
      const lod = await parseGlb(await (await fetch(`${base}/lods/${k}`)).arrayBuffer(), origin);
      viewer.setMesh(lod, origin !== null);
      origin = lod.origin;
      console.info(`level of detail ${k}: ${lod.indices.length / 3} triangles`);
      setStatus(`level of detail ${k}: ${lod.indices.length / 3} triangles; loading the full mesh…`);
    }
    const buf = await (await fetch(`${base}/mesh.glb`)).arrayBuffer();
    const mesh = await parseGlb(buf, origin);
    viewer.setMesh(mesh, origin !== null);
    setStatus(`loaded ${mesh.indices.length / 3} triangles` + (mesh.colored ? " with vertex colours" : ""));
  } catch (e) {
    setStatus("Cannot display the mesh: " + e.message, true);
  }
}

function showStats(r) {
  if (!r) return;
  if (r.frames) {
    $("stats").innerHTML = r.frames.map((f) => `<tr><td>t = ${f.t.toFixed(2)}</td><td>${f.triangles} triangles, ` +
      `${f.components} comp., genus ${f.genus ?? "-"}, watertight ${f.watertight}</td></tr>`).join("");
    return;
  }
  if (!r.input) {
    const m = r.mesh;
    $("stats").innerHTML = [["expression", r.expression], ["triangles", m.triangles], ["components", m.components],
      ["watertight", m.watertight], ["genus", m.genus], ["blocks evaluated", `${r.blocks_active} of ${r.blocks_total}`],
      ["total time", r.timings_s.total.toFixed(2) + " s"]]
      .map(([k, v]) => `<tr><td>${k}</td><td>${v}</td></tr>`).join("");
    return;
  }
  const rows = [
    ["points used", `${r.input.used} of ${r.input.points}`],
    ["triangles", r.mesh.triangles], ["vertices", r.mesh.vertices],
    ["components", r.mesh.components], ["watertight", r.mesh.watertight],
    ["manifold", r.mesh.manifold], ["genus", r.mesh.genus],
    ["kernel", r.params.kernel], ["carrier", r.params.carrier],
    ["support", r.params.support.toPrecision(3)], ["resolution", r.params.resolution],
    ["matrix nnz", r.matrix.nnz], ["residual max", r.residual.max.toExponential(1)],
    ["total time", r.timings_s.total.toFixed(2) + " s"], ["peak memory", r.memory.peak_rss_mib.toFixed(0) + " MiB"],
  ];
  $("stats").innerHTML = rows.map(([k, v]) => `<tr><td>${k}</td><td>${v}</td></tr>`).join("");
}

// ---------- GLB reader ----------
// Plain float glTF or the compact form rbfsurf writes by default: KHR_mesh_quantization (integer
// positions dequantized by the node's translation/rotation/scale, normalized byte normals, short
// colours) and EXT_meshopt_compression (bufferViews decoded with the vendored meshoptimizer
// decoder, /assets/meshopt_decoder.mjs, loaded on first use; no network access beyond this server).
let meshoptDecoder = null;
async function meshopt() {
  if (!meshoptDecoder) {
    const { MeshoptDecoder } = await import("/assets/meshopt_decoder.mjs");
    await MeshoptDecoder.ready;
    meshoptDecoder = MeshoptDecoder;
  }
  return meshoptDecoder;
}

// Decoded bytes of every bufferView: { bytes: Uint8Array, stride }.
async function viewBytes(json, bin) {
  const views = json.bufferViews || [];
  const compressed = views.some((v) => v.extensions && v.extensions.EXT_meshopt_compression);
  const dec = compressed ? await meshopt() : null;
  return views.map((v) => {
    const ext = v.extensions && v.extensions.EXT_meshopt_compression;
    if (!ext) return { bytes: new Uint8Array(bin, v.byteOffset || 0, v.byteLength), stride: v.byteStride || 0 };
    const source = new Uint8Array(bin, ext.byteOffset || 0, ext.byteLength);
    const target = new Uint8Array(ext.count * ext.byteStride);
    dec.decodeGltfBuffer(target, ext.count, ext.byteStride, source, ext.mode, ext.filter);
    return { bytes: target, stride: ext.byteStride };
  });
}

// A node's local matrix (column-major 4×4) from matrix or translation/rotation/scale.
function nodeMatrix(n) {
  if (n.matrix) return n.matrix;
  const [x, y, z, w] = n.rotation || [0, 0, 0, 1], s = n.scale || [1, 1, 1], t = n.translation || [0, 0, 0];
  return [(1 - 2 * (y * y + z * z)) * s[0], 2 * (x * y + z * w) * s[0], 2 * (x * z - y * w) * s[0], 0,
          2 * (x * y - z * w) * s[1], (1 - 2 * (x * x + z * z)) * s[1], 2 * (y * z + x * w) * s[1], 0,
          2 * (x * z + y * w) * s[2], 2 * (y * z - x * w) * s[2], (1 - 2 * (x * x + y * y)) * s[2], 0,
          t[0], t[1], t[2], 1];
}

async function parseGlb(buf, origin) {
  const dv = new DataView(buf);
  if (buf.byteLength < 20 || dv.getUint32(0, true) !== 0x46546c67) throw new Error("not a GLB file");
  let off = 12, json = null, bin = null;
  while (off + 8 <= buf.byteLength) {
    const len = dv.getUint32(off, true), type = dv.getUint32(off + 4, true);
    const start = off + 8;
    if (type === 0x4e4f534a) json = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, start, len)));
    else if (type === 0x004e4942) bin = buf.slice(start, start + len);
    off = start + len;
  }
  if (!json || !bin) throw new Error("GLB without JSON or BIN chunk");
  const views = await viewBytes(json, bin);
  const Types = { 5120: Int8Array, 5121: Uint8Array, 5122: Int16Array, 5123: Uint16Array, 5125: Uint32Array, 5126: Float32Array };
  const Norm = { 5120: 127, 5121: 255, 5122: 32767, 5123: 65535 };
  // Accessor values as numbers (normalized integers scaled to [-1, 1] / [0, 1]).
  const read = (index, comps) => {
    const acc = json.accessors[index];
    const view = views[acc.bufferView];
    const T = Types[acc.componentType];
    if (!T) throw new Error("unsupported component type " + acc.componentType);
    const size = T.BYTES_PER_ELEMENT;
    const stride = view.stride || size * comps;
    const src = new DataView(view.bytes.buffer, view.bytes.byteOffset, view.bytes.byteLength);
    const get = { 5120: (o) => src.getInt8(o), 5121: (o) => src.getUint8(o), 5122: (o) => src.getInt16(o, true),
      5123: (o) => src.getUint16(o, true), 5125: (o) => src.getUint32(o, true), 5126: (o) => src.getFloat32(o, true) }[acc.componentType];
    const scale = acc.normalized ? 1 / Norm[acc.componentType] : 1;
    const out = new (acc.componentType === 5125 ? Uint32Array : Float64Array)(acc.count * comps);
    for (let i = 0; i < acc.count; i++)
      for (let c = 0; c < comps; c++) {
        const v = get((acc.byteOffset || 0) + i * stride + c * size) * scale;
        out[i * comps + c] = acc.normalized && v < -1 ? -1 : v;
      }
    return out;
  };
  // Positions through the node matrix, relative to `origin` (f64 until then: far-from-origin
  // scans keep their precision); normals through its linear part, renormalised. A singular matrix
  // (a hidden morph frame, scale 0) moves by its translation only.
  const place = (p, n, m) => {
    const det = m[0] * (m[5] * m[10] - m[9] * m[6]) - m[4] * (m[1] * m[10] - m[9] * m[2]) + m[8] * (m[1] * m[6] - m[5] * m[2]);
    const lin = Math.abs(det) > 1e-30 ? m : [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0];
    const pos = new Float32Array(p.length);
    for (let i = 0; i < p.length; i += 3)
      for (let d = 0; d < 3; d++)
        pos[i + d] = lin[d] * p[i] + lin[4 + d] * p[i + 1] + lin[8 + d] * p[i + 2] + (m[12 + d] - origin[d]);
    if (!n) return { pos, nrm: null };
    const nrm = new Float32Array(n.length);
    for (let i = 0; i < n.length; i += 3) {
      // Uniform scale and rotation: the linear part itself, renormalised.
      const v = [0, 1, 2].map((d) => lin[d] * n[i] + lin[4 + d] * n[i + 1] + lin[8 + d] * n[i + 2]);
      const l = Math.hypot(...v) || 1;
      for (let d = 0; d < 3; d++) nrm[i + d] = v[d] / l;
    }
    return { pos, nrm };
  };
  const nodes = json.nodes || [];
  if (!origin) {
    const first = nodes.find((n) => n.mesh === 0);
    origin = (first && first.translation) || [0, 0, 0];
  }
  const meshOf = (index) => {
    const prim = json.meshes[index].primitives[0];
    const node = nodes.find((n) => n.mesh === index);
    const { pos: positions, nrm } = place(read(prim.attributes.POSITION, 3),
      prim.attributes.NORMAL !== undefined ? read(prim.attributes.NORMAL, 3) : null,
      node ? nodeMatrix(node) : nodeMatrix({}));
    const indices = Uint32Array.from(read(prim.indices, 1));
    const normals = nrm || vertexNormals(positions, indices);
    const colored = prim.attributes.COLOR_0 !== undefined;
    return { positions, normals, indices, colored, origin, colors: colored ? vertexColors(json, prim, read, positions.length / 3) : null };
  };
  const first = meshOf(0);
  // A morph: one node per frame (scene order), shown one at a time by a STEP animation.
  if (json.animations && json.animations.length && json.meshes.length > 1) {
    const frameNodes = json.scenes[json.scene || 0].nodes.map((n) => nodes[n]);
    first.frames = frameNodes.map((n) => (n.mesh === 0 ? first : meshOf(n.mesh)));
    const times = read(json.animations[0].samplers[0].input, 1);
    first.frameSeconds = times.length > 1 ? times[1] - times[0] : 0.25;
  }
  return first;
}

// COLOR_0 as sRGB-encoded floats for display (the file holds linear RGB, VEC3 or VEC4; float or
// normalized unsigned byte/short, which `read` already scaled to [0, 1]).
function vertexColors(json, prim, read, n) {
  const acc = json.accessors[prim.attributes.COLOR_0];
  const comps = acc.type === "VEC4" ? 4 : 3;
  const raw = read(prim.attributes.COLOR_0, comps);
  const out = new Float32Array(n * 3);
  const encode = (c) => c <= 0.0031308 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055;
  for (let i = 0; i < n; i++)
    for (let d = 0; d < 3; d++) out[i * 3 + d] = encode(Math.min(1, Math.max(0, raw[i * comps + d])));
  return out;
}

function vertexNormals(p, idx) {
  const n = new Float32Array(p.length);
  for (let t = 0; t < idx.length; t += 3) {
    const [a, b, c] = [idx[t] * 3, idx[t + 1] * 3, idx[t + 2] * 3];
    const u = [p[b] - p[a], p[b + 1] - p[a + 1], p[b + 2] - p[a + 2]];
    const v = [p[c] - p[a], p[c + 1] - p[a + 1], p[c + 2] - p[a + 2]];
    const f = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    for (const k of [a, b, c]) for (let d = 0; d < 3; d++) n[k + d] += f[d];
  }
  return n;
}

// ---------- WebGL viewer ----------
function createViewer(canvas) {
  const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: true }) ||
             canvas.getContext("webgl", { preserveDrawingBuffer: true, antialias: true });
  if (!gl) { setStatus("WebGL is not available in this browser.", true); return { setMesh() {} }; }
  const isGl2 = typeof WebGL2RenderingContext !== "undefined" && gl instanceof WebGL2RenderingContext;
  if (!isGl2 && !gl.getExtension("OES_element_index_uint")) setStatus("32-bit indices unsupported.", true);
  const vs = `attribute vec3 aPos; attribute vec3 aNrm; attribute vec3 aCol; uniform mat4 uMvp; uniform mat4 uView;
    varying vec3 vN; varying vec3 vC;
    void main() { gl_Position = uMvp * vec4(aPos, 1.0); vN = mat3(uView) * aNrm; vC = aCol; }`;
  const fs = `precision mediump float; varying vec3 vN; varying vec3 vC;
    void main() { vec3 n = normalize(vN); float d = abs(n.z);
      gl_FragColor = vec4(vC * (0.25 + 0.75 * d) + vec3(0.15) * pow(d, 24.0), 1.0); }`;
  const compile = (type, src) => {
    const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  };
  const prog = gl.createProgram();
  gl.attachShader(prog, compile(gl.VERTEX_SHADER, vs));
  gl.attachShader(prog, compile(gl.FRAGMENT_SHADER, fs));
  gl.linkProgram(prog);
  const loc = { pos: gl.getAttribLocation(prog, "aPos"), nrm: gl.getAttribLocation(prog, "aNrm"),
    col: gl.getAttribLocation(prog, "aCol"),
    mvp: gl.getUniformLocation(prog, "uMvp"), view: gl.getUniformLocation(prog, "uView") };
  const state = { yaw: 0.6, pitch: 0.35, dist: 3.4, count: 0, center: [0, 0, 0], scale: 1 };
  let buffers = null;

  let frames = [], timer = null;
  // Shows `m`; `refine`: a finer level of detail of the mesh shown (same frame, camera kept).
  function setMesh(m, refine) {
    const list = m.frames || [m];
    let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const f of list)
      for (let i = 0; i < f.positions.length; i += 3)
        for (let d = 0; d < 3; d++) { lo[d] = Math.min(lo[d], f.positions[i + d]); hi[d] = Math.max(hi[d], f.positions[i + d]); }
    if (!refine) {
      state.center = lo.map((l, d) => (l + hi[d]) / 2);
      state.scale = 2 / Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-30);
    }
    const mk = (target, data) => { const b = gl.createBuffer(); gl.bindBuffer(target, b); gl.bufferData(target, data, gl.STATIC_DRAW); return b; };
    const colorsOf = (f) => {
      if (f.colors) return f.colors;
      const c = new Float32Array(f.positions.length);
      for (let i = 0; i < c.length; i += 3) c.set([0.88, 0.53, 0.23], i);
      return c;
    };
    for (const f of frames) for (const b of [f.pos, f.nrm, f.col, f.idx]) gl.deleteBuffer(b);
    frames = list.map((f) => ({ pos: mk(gl.ARRAY_BUFFER, f.positions), nrm: mk(gl.ARRAY_BUFFER, new Float32Array(f.normals)),
      col: mk(gl.ARRAY_BUFFER, colorsOf(f)), idx: mk(gl.ELEMENT_ARRAY_BUFFER, f.indices), count: f.indices.length }));
    if (timer) clearInterval(timer);
    timer = null;
    let k = 0;
    const show = () => { buffers = frames[k]; state.count = buffers.count; };
    show();
    if (frames.length > 1) {
      // Play the morph: each frame for its duration, a pause at both ends.
      timer = setInterval(() => { k = (k + 1) % (frames.length + 2); if (k < frames.length) { show(); draw(); } },
        1000 * (m.frameSeconds || 0.25));
    }
    if (refine) draw(); else resetView();
  }

  function resetView() { state.yaw = 0.6; state.pitch = 0.35; state.dist = 3.4; draw(); }

  function draw() {
    const w = canvas.clientWidth * devicePixelRatio | 0, h = canvas.clientHeight * devicePixelRatio | 0;
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, w, h);
    gl.clearColor(0.114, 0.129, 0.153, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (!buffers) return;
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(prog);
    const s = state.scale, c = state.center;
    const model = [s, 0, 0, 0, 0, s, 0, 0, 0, 0, s, 0, -c[0] * s, -c[1] * s, -c[2] * s, 1];
    const eye = [state.dist * Math.cos(state.pitch) * Math.sin(state.yaw), state.dist * Math.sin(state.pitch),
                 state.dist * Math.cos(state.pitch) * Math.cos(state.yaw)];
    const view = mul(lookAt(eye, [0, 0, 0], [0, 1, 0]), model);
    const proj = perspective(0.8, w / Math.max(h, 1), 0.01, 100);
    gl.uniformMatrix4fv(loc.mvp, false, mul(proj, view));
    gl.uniformMatrix4fv(loc.view, false, view);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffers.pos);
    gl.enableVertexAttribArray(loc.pos); gl.vertexAttribPointer(loc.pos, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffers.nrm);
    gl.enableVertexAttribArray(loc.nrm); gl.vertexAttribPointer(loc.nrm, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffers.col);
    gl.enableVertexAttribArray(loc.col); gl.vertexAttribPointer(loc.col, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, buffers.idx);
    gl.drawElements(gl.TRIANGLES, state.count, gl.UNSIGNED_INT, 0);
  }

  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    state.yaw -= (e.clientX - drag[0]) * 0.01;
    state.pitch = Math.max(-1.5, Math.min(1.5, state.pitch + (e.clientY - drag[1]) * 0.01));
    drag = [e.clientX, e.clientY];
    draw();
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    state.dist = Math.max(0.3, Math.min(50, state.dist * Math.exp(e.deltaY * 0.001)));
    draw();
  }, { passive: false });
  canvas.addEventListener("dblclick", resetView);
  addEventListener("resize", draw);
  draw();
  return { setMesh, draw };
}

// Column-major 4×4 helpers.
function mul(a, b) {
  const o = new Array(16).fill(0);
  for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) for (let k = 0; k < 4; k++) o[j * 4 + i] += a[k * 4 + i] * b[j * 4 + k];
  return o;
}
function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
}
function lookAt(eye, at, up) {
  const norm = (v) => { const l = Math.hypot(...v) || 1; return v.map((x) => x / l); };
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const z = norm(eye.map((e, i) => e - at[i])), x = norm(cross(up, z)), y = cross(z, x);
  return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
}

// ---------- wiring ----------
const viewer = createViewer($("view"));
const drop = $("drop");
drop.addEventListener("click", () => $("file").click());
$("file").addEventListener("change", (e) => choose(e.target.files[0]));
drop.addEventListener("dragover", (e) => { e.preventDefault(); drop.classList.add("over"); });
drop.addEventListener("dragleave", () => drop.classList.remove("over"));
drop.addEventListener("drop", (e) => {
  e.preventDefault();
  drop.classList.remove("over");
  if (e.dataTransfer.files.length) choose(e.dataTransfer.files[0]);
});
$("go").addEventListener("click", submit);

// ---------- volume modelling: compose or morph two finished jobs ----------
async function refreshJobs() {
  try {
    const list = await (await fetch("/v1/reconstructions")).json();
    const done = list.filter((j) => j.status === "succeeded" && !["composition", "morph"].includes(j.input.format));
    for (const id of ["opA", "opB"]) {
      const sel = $(id), keep = sel.value;
      sel.innerHTML = done.map((j) => `<option value="${j.id}">${j.id.slice(0, 8)} · ${j.input.points} pts · ${j.triangles} tri</option>`).join("");
      if (keep) sel.value = keep;
    }
    $("compose").disabled = done.length < 1;
  } catch (e) { /* the list is optional */ }
}

async function compose() {
  const a = $("opA").value, b = $("opB").value, op = $("op").value, amount = $("amount").value.trim();
  const headers = { "Content-Type": "application/json" };
  const token = $("token").value.trim();
  if (token) headers["Authorization"] = "Bearer " + token;
  let url = "/v1/compositions", body;
  if (op === "morph") {
    url = "/v1/morphs";
    body = { a, b, frames: amount ? Number(amount) : 8 };
  } else if (op === "blend") {
    body = { expression: `blend(${a}, ${b}, ${amount || "0.05"})` };
  } else {
    body = { expression: `${op}(${a}, ${b})` };
  }
  setStatus("Submitting…");
  try {
    const r = await fetch(url, { method: "POST", headers, body: JSON.stringify(body) });
    const v = await r.json();
    if (!r.ok) throw new Error(v.error ? `${v.error.code}: ${v.error.message}` : `HTTP ${r.status}`);
    location.hash = "job=" + v.id;
    follow(v.id);
  } catch (e) {
    setStatus("Failed: " + e.message, true);
  }
}
$("compose").addEventListener("click", compose);
refreshJobs();
const m = location.hash.match(/job=([0-9a-f-]{36})/);
if (m) follow(m[1]);
