// QuadLoc inspector: no framework, no CDN. Talks to the same server's REST API.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const state = { map: null, result: null, request: null, yaw: 0.8, pitch: 0.5, zoom: 1.0 };

  function headers(extra) {
    const h = Object.assign({}, extra || {});
    const key = $("api-key").value.trim();
    if (key) h["Authorization"] = "Bearer " + key;
    return h;
  }
  function setStatus(text, st) {
    const el = $("status");
    el.textContent = text;
    el.dataset.state = st;
  }
  async function problemText(r) {
    try {
      const p = await r.json();
      const errs = (p.errors || []).map((e) => e.field + ": " + e.message).join("; ");
      return r.status + " " + (p.title || "") + ": " + (p.detail || "") + (errs ? " [" + errs + "]" : "");
    } catch (e) {
      return r.status + " " + r.statusText;
    }
  }

  async function loadMaps() {
    sessionStorage.setItem("quadloc-api-key", $("api-key").value);
    const r = await fetch("/v1/maps", { headers: headers({ Accept: "application/json" }) });
    if (!r.ok) { setStatus("Listing maps failed: " + (await problemText(r)), "error"); return; }
    const body = await r.json();
    const sel = $("map");
    const previous = sel.value;
    sel.innerHTML = "";
    for (const m of body.maps) {
      const o = document.createElement("option");
      o.value = m.map_id;
      o.textContent = m.map_id + " (v" + m.version + ", " + m.name + ")";
      sel.appendChild(o);
    }
    if (previous) sel.value = previous;
    await showMap();
  }

  async function loadExample() {
    const r = await fetch("/inspector/example.json");
    $("request").value = JSON.stringify(await r.json(), null, 2);
    if ([...$("map").options].some((o) => o.value === "chess") && $("map").value !== "chess") {
      $("map").value = "chess";
      await showMap();
    }
  }

  // The previous answer goes as soon as a new request starts: a failure must not leave it
  // under its error (the map stays in the 3D view, without the camera).
  function clearResult() {
    state.result = null;
    state.request = null;
    $("overlay").replaceChildren();
    $("inliers").querySelector("tbody").replaceChildren();
    fillCandidates(null);
    draw3d();
  }

  // The selected map's latest version in the 3D view (before any localize, and on a change).
  async function showMap() {
    const mapId = $("map").value;
    if (!mapId) { state.map = null; draw3d(); return; }
    const r = await fetch("/v1/maps/" + encodeURIComponent(mapId),
                          { headers: headers({ Accept: "application/json" }) });
    if ($("map").value !== mapId) return;  // the user picked another map meanwhile
    if (!r.ok) { setStatus("Loading the map failed: " + (await problemText(r)), "error"); return; }
    state.map = (await r.json()).map;
    state.result = null;
    state.request = null;
    draw3d();
  }

  async function localize() {
    clearResult();
    const mapId = $("map").value;
    if (!mapId) { setStatus("No map selected.", "error"); return; }
    let request;
    try { request = JSON.parse($("request").value); } catch (e) {
      setStatus("The request is not valid JSON: " + e.message, "error"); return;
    }
    setStatus("Localizing...", "busy");
    const r = await fetch("/v1/maps/" + encodeURIComponent(mapId) + "/localize", {
      method: "POST", body: JSON.stringify(request),
      headers: headers({ "Content-Type": "application/json", Accept: "image/svg+xml" }),
    });
    if (!r.ok) { setStatus("Localize failed: " + (await problemText(r)), "error"); return; }
    const doc = new DOMParser().parseFromString(await r.text(), "image/svg+xml");
    const svg = document.importNode(doc.documentElement, true);
    $("overlay").replaceChildren(svg);
    const meta = svg.querySelector("#quadloc-result");
    const result = JSON.parse(meta.textContent);
    state.result = result;
    state.request = request;
    const m = await fetch("/v1/maps/" + encodeURIComponent(mapId) + "?version=" + result.map_version,
                          { headers: headers({ Accept: "application/json" }) });
    state.map = m.ok ? (await m.json()).map : null;
    fillInliers(request, result);
    fillCandidates(result);
    draw3d();
    if (result.localized) {
      const t = result.world_from_camera.translation_m.map((x) => x.toFixed(3)).join(", ");
      setStatus("Localized: confidence " + result.confidence.toFixed(2) + ", " +
                result.inliers.length + "/" + request.detections.length + " inliers, camera at [" +
                t + "] m" + (result.zone ? " in zone " + result.zone : "") + " (map " +
                result.map_id + " v" + result.map_version + ")", "done");
    } else {
      const n = result.alternatives.length;
      setStatus("Not localized: " + result.reason + (n ? " (" + n + " candidate place" +
                (n > 1 ? "s" : "") + ", listed below)" : "") + " (map " + result.map_id + " v" +
                result.map_version + ")", "not-localized");
    }
  }

  function fillInliers(request, result) {
    const tbody = $("inliers").querySelector("tbody");
    tbody.replaceChildren();
    const byDet = new Map(result.inliers.map((m) => [m.detection_index, m]));
    request.detections.forEach((d, i) => {
      const m = byDet.get(i);
      const tr = document.createElement("tr");
      const cells = [String(i), d.label, m ? m.object_id : "outlier",
                     m ? m.iou.toFixed(2) : "", m ? m.cost.toPrecision(3) : ""];
      for (const c of cells) { const td = document.createElement("td"); td.textContent = c; tr.appendChild(td); }
      tbody.appendChild(tr);
    });
  }

  // The candidate places of an answer with alternatives (ambiguous, low confidence...): zone,
  // camera position (map frame, m), probability and score; hidden when there are none.
  function fillCandidates(result) {
    const table = $("candidates");
    const tbody = table.querySelector("tbody");
    tbody.replaceChildren();
    const alts = (result && result.alternatives) || [];
    table.hidden = alts.length === 0;
    alts.forEach((a, k) => {
      const tr = document.createElement("tr");
      const t = a.world_from_camera.translation_m.map((x) => x.toFixed(2)).join(", ");
      const cells = [String(k), a.zone === null || a.zone === undefined ? "-" : a.zone,
                     "[" + t + "]", a.confidence.toFixed(3), a.score.toFixed(2)];
      for (const c of cells) { const td = document.createElement("td"); td.textContent = c; tr.appendChild(td); }
      tbody.appendChild(tr);
    });
  }

  // ---------------------------------------------------------------- 3D view (hand-written)
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const mul = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => mul(a, 1 / Math.hypot(a[0], a[1], a[2]));
  const matvec = (R, v) => [dot(R[0], v), dot(R[1], v), dot(R[2], v)];

  function rotationWxyz(q) {  // ellipsoid -> world
    const n = Math.hypot(q[0], q[1], q[2], q[3]);
    const [w, x, y, z] = q.map((v) => v / n);
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]];
  }

  function polylines() {
    const lines = [];
    const matched = new Set((state.result && state.result.inliers || []).map((m) => m.object_id));
    for (const o of state.map.objects) {
      const R = rotationWxyz(o.quaternion_wxyz || [1, 0, 0, 0]);
      const color = matched.has(String(o.object_id)) ? "#3fb950" : "#58a6ff";
      for (const [i, j] of [[0, 1], [1, 2], [0, 2]]) {
        const pts = [];
        for (let k = 0; k <= 48; k++) {
          const t = (2 * Math.PI * k) / 48;
          const local = [0, 0, 0];
          local[i] = o.axes[i] * Math.cos(t);
          local[j] = o.axes[j] * Math.sin(t);
          pts.push(add(o.center, matvec(R, local)));
        }
        lines.push({ pts, color, width: 1 });
      }
    }
    const res = state.result;
    if (res && res.localized && state.request) {
      frustum(lines, res.world_from_camera, "#f0883e", 0.25 * sceneRadius());
    }
    return lines;
  }

  const CANDIDATE = "#d2a8ff";  // violet: the candidate places of an answer not localized

  // The candidates drawn: those of an answer that is not localized (a localized answer's
  // pose is its frustum; its runners-up are in the table).
  function candidates() {
    const res = state.result;
    return res && !res.localized && state.request ? res.alternatives : [];
  }

  // The camera frustum of `pose` (the answer's world_from_camera) pushed onto `lines`; returns
  // the camera centre (map frame, m).
  function frustum(lines, pose, color, depth) {
    const T = pose.matrix;
    const flip = pose.convention === "opengl" ? [1, -1, -1] : [1, 1, 1];
    const R = [0, 1, 2].map((r) => [0, 1, 2].map((c) => T[r][c] * flip[c]));  // OpenCV axes
    const C = [T[0][3], T[1][3], T[2][3]];
    const cam = state.request.camera;
    const corners = [[0, 0], [cam.width, 0], [cam.width, cam.height], [0, cam.height]].map(
      ([u, v]) => add(C, mul(matvec(R, [(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1]), depth)));
    for (const p of corners) lines.push({ pts: [C, p], color, width: 2 });
    lines.push({ pts: corners.concat([corners[0]]), color, width: 2 });
    // "up" tick of the image (-y in OpenCV camera axes) so the roll is visible
    const top = mul(add(corners[0], corners[1]), 0.5);
    lines.push({ pts: [top, add(top, mul(matvec(R, [0, -1, 0]), depth * 0.3))], color, width: 2 });
    return C;
  }

  function sceneCenter() {
    const cs = state.map.objects.map((o) => o.center);
    if (!cs.length) return [0, 0, 0];
    return mul(cs.reduce(add, [0, 0, 0]), 1 / cs.length);
  }
  function sceneRadius() {
    const c = sceneCenter();
    let r = 0.5;
    for (const o of state.map.objects) r = Math.max(r, Math.hypot(...sub(o.center, c)) + Math.max(...o.axes));
    return r;
  }

  function draw3d() {
    const canvas = $("view3d");
    const g = canvas.getContext("2d");
    g.clearRect(0, 0, canvas.width, canvas.height);
    canvas.dataset.camera = String(Boolean(state.result && state.result.localized));
    if (!state.map) { canvas.dataset.drawn = "0"; canvas.dataset.candidates = "0"; return; }
    const up = norm(state.map.up_axis || [0, 0, 1]);
    const any = Math.abs(up[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
    const e1 = norm(cross(up, any));
    const e2 = cross(up, e1);
    const target = sceneCenter();
    const radius = 2.6 * sceneRadius() / state.zoom;
    const dir = add(mul(add(mul(e1, Math.cos(state.yaw)), mul(e2, Math.sin(state.yaw))), Math.cos(state.pitch)),
                    mul(up, Math.sin(state.pitch)));
    const eye = add(target, mul(dir, radius));
    const fwd = norm(sub(target, eye));
    const right = norm(cross(fwd, up));
    const camUp = cross(right, fwd);
    const f = canvas.height * 1.1;
    const project = (p) => {
      const d = sub(p, eye);
      const z = dot(d, fwd);
      if (z < 1e-3) return null;
      return [canvas.width / 2 + (f * dot(d, right)) / z, canvas.height / 2 - (f * dot(d, camUp)) / z];
    };
    const lines = polylines();
    const labels = [];
    candidates().forEach((a, k) => {  // frusta numbered as the table's rows
      const C = frustum(lines, a.world_from_camera, CANDIDATE, 0.12 * sceneRadius());
      labels.push({ at: C, text: "#" + k + (a.zone ? " " + a.zone : "") });
    });
    canvas.dataset.candidates = String(labels.length);
    for (const line of lines) {
      g.strokeStyle = line.color;
      g.lineWidth = line.width;
      g.beginPath();
      let pen = false;
      for (const p of line.pts) {
        const s = project(p);
        if (!s) { pen = false; continue; }
        if (pen) g.lineTo(s[0], s[1]); else g.moveTo(s[0], s[1]);
        pen = true;
      }
      g.stroke();
    }
    g.fillStyle = CANDIDATE;
    g.font = "13px system-ui, sans-serif";
    for (const l of labels) {
      const p = project(l.at);
      if (p) g.fillText(l.text, p[0] + 6, p[1] - 6);
    }
    canvas.dataset.drawn = String(state.map.objects.length);
  }

  function setup3dControls() {
    const canvas = $("view3d");
    let drag = null;
    canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; });
    window.addEventListener("mouseup", () => { drag = null; });
    window.addEventListener("mousemove", (e) => {
      if (!drag) return;
      state.yaw -= (e.clientX - drag[0]) * 0.01;
      state.pitch = Math.max(-1.5, Math.min(1.5, state.pitch + (e.clientY - drag[1]) * 0.01));
      drag = [e.clientX, e.clientY];
      draw3d();
    });
    canvas.addEventListener("wheel", (e) => {
      e.preventDefault();
      state.zoom = Math.max(0.2, Math.min(10, state.zoom * (e.deltaY < 0 ? 1.1 : 1 / 1.1)));
      draw3d();
    });
  }

  $("key-form").addEventListener("submit", (e) => { e.preventDefault(); loadMaps(); });
  $("api-key").value = sessionStorage.getItem("quadloc-api-key") || "";
  $("api-key").addEventListener("change", loadMaps);
  $("load-example").addEventListener("click", loadExample);
  $("map").addEventListener("change", () => showMap().catch((e) => setStatus(String(e), "error")));
  $("localize").addEventListener("click", () => localize().catch((e) => setStatus(String(e), "error")));
  $("upload").addEventListener("change", async (e) => {
    const file = e.target.files[0];
    if (file) $("request").value = await file.text();
  });
  setup3dControls();
  loadMaps().catch((e) => setStatus(String(e), "error"));
})();
