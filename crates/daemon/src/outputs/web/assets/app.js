// The lightpose page: the daemon's live feed (server-sent events at
// v1/events: a "live" event several times a second, a "status" event at
// each STATUS) drawn as heatmaps, the pose, the track and the health
// tables. Every address is relative: BlueOS serves the page under a
// prefix of its own.
"use strict";

// What the page has seen, for a person debugging it and for the tests.
const seen = { live: 0, status: 0, errors: [], connects: 0, lastStatus: null, lastPose: null };
window.lightpose = seen;
window.addEventListener("error", (e) => seen.errors.push(String(e.message)));

// Why a pose is not ok, in words (the estimator's status words, FORMATS.md).
const WHY = {
  no_light: "Too little light on the array to tell anything: the beacon is off, hidden, or out of view.",
  saturated: "Photodiodes at full scale distort the image: the vehicle is too close, or the gain too high.",
  out_of_range: "The vehicle is outside the range of poses the calibration covered.",
  initialising: "The estimator needs a few more frames before it can say everything.",
  bad_frame: "The frame itself is unusable (wrong resolution, a bus error, garbage).",
  diverged: "The solver did not converge on this frame.",
  unobservable: "Some fields lie along a direction the light does not determine (no attitude reading): their σ is no guarantee.",
  daylight: "Daylight on the array is more than the estimator can tell from a steady beacon's light.",
  none: "No frame estimated yet.",
};

const $ = (id) => document.getElementById(id);
const TRACK_S = 30;
const track = []; // {t (s, wall), x, y, z}

function fmt(v, digits) {
  return v === null || v === undefined || !Number.isFinite(v) ? "—" : v.toFixed(digits);
}

function withSigma(v, s, digits, unit) {
  if (v === null || v === undefined) return "—";
  const sig = s === null || s === undefined ? "" : ` ± ${fmt(2 * s, digits)}`;
  return `${fmt(v, digits)}${sig} ${unit}`;
}

// --- heatmaps --------------------------------------------------------------

function heatColour(f) {
  // Dark blue through yellow to white: the brightest photodiode stands out.
  const c = Math.max(0, Math.min(1, f));
  const r = Math.round(255 * Math.min(1, c * 1.6));
  const g = Math.round(255 * Math.max(0, Math.min(1, c * 1.6 - 0.4)));
  const b = Math.round(255 * Math.max(0.15 - c * 0.15, c > 0.85 ? (c - 0.85) / 0.15 : 0));
  return `rgb(${r},${g},${Math.max(40 * (1 - c), b)})`;
}

function drawHeatmap(canvas, values, scale, label) {
  const ctx = canvas.getContext("2d");
  const n = 5, w = canvas.width / n, h = canvas.height / n;
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.font = `${Math.round(h / 4)}px system-ui`;
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  for (let r = 0; r < n; r++) {
    for (let c = 0; c < n; c++) {
      const v = values[r * n + c];
      const f = v === null ? 0 : v / scale;
      ctx.fillStyle = heatColour(f);
      ctx.fillRect(c * w + 1, r * h + 1, w - 2, h - 2);
      ctx.fillStyle = f > 0.55 ? "#000" : "#cde";
      ctx.fillText(v === null ? "?" : String(Math.round(v)), c * w + w / 2, r * h + h / 2);
    }
  }
  canvas.dataset.drawn = String((Number(canvas.dataset.drawn) || 0) + 1);
  canvas.title = label;
}

function heatmapCanvas(i, label) {
  const box = $("heatmaps");
  let fig = box.children[i];
  if (!fig) {
    fig = document.createElement("figure");
    const cv = document.createElement("canvas");
    cv.width = 250; cv.height = 250; cv.className = "heatmap";
    fig.appendChild(cv);
    fig.appendChild(document.createElement("figcaption"));
    box.appendChild(fig);
  }
  fig.querySelector("figcaption").textContent = label;
  return fig.querySelector("canvas");
}

function showImage(frame) {
  const beacons = frame.beacons || [];
  const maps = beacons.length > 0
    ? beacons.map((b) => ({ values: b.amplitude, label: `beacon ${b.beacon} amplitude` }))
    : [{ values: frame.counts, label: `counts of ${frame.full_scale}` }];
  $("image-kind").textContent = beacons.length > 0 ? `${beacons.length} beacon(s), demodulated` : "counts";
  const box = $("heatmaps");
  while (box.children.length > maps.length) box.removeChild(box.lastChild);
  maps.forEach((m, i) => {
    const finite = m.values.filter((v) => v !== null);
    // Against the brightest photodiode, so that a far beacon still shows
    // its spot; counts never against less than an eighth of full scale,
    // so that a dark array looks dark and a saturated one white.
    const brightest = Math.max(1, ...finite);
    const scale = beacons.length > 0 ? brightest : Math.max(brightest, frame.full_scale / 8);
    drawHeatmap(heatmapCanvas(i, m.label), m.values, scale, m.label);
  });
}

// --- pose and track ----------------------------------------------------------

function showPose(p, frame) {
  seen.lastPose = p;
  const s = p.std || {};
  $("p-x").textContent = withSigma(p.x, s.x, 2, "m");
  $("p-y").textContent = withSigma(p.y, s.y, 2, "m");
  $("p-z").textContent = withSigma(p.z, s.z, 2, "m");
  $("p-pitch").textContent = withSigma(p.pitch, s.pitch, 1, "°");
  $("p-yaw").textContent = withSigma(p.yaw, s.yaw, 1, "°");
  $("p-roll").textContent = p.roll === undefined ? "not known" : withSigma(p.roll, s.roll, 1, "°");
  $("p-surge").textContent = withSigma(p.surge, s.surge, 2, "m/s");
  $("p-seq").textContent = `${p.seq}`;
  showStatusWord(p.status);
  if (p.x !== null && p.y !== null) {
    const t = frame.wall || Date.now() / 1000;
    track.push({ t, x: p.x, y: p.y, z: p.z === null ? NaN : p.z, ok: p.status === "ok" });
    while (track.length && track[0].t < t - TRACK_S) track.shift();
    drawTrack($("top"), "y");
    drawTrack($("side"), "z");
  }
}

function drawTrack(canvas, other) {
  const ctx = canvas.getContext("2d");
  const W = canvas.width, H = canvas.height, pad = 28;
  ctx.clearRect(0, 0, W, H);
  const pts = track.filter((p) => Number.isFinite(p[other]));
  // The beacon (0, 0) is always in view, with the track.
  let xmax = 1, omin = -0.5, omax = 0.5;
  for (const p of pts) { xmax = Math.max(xmax, p.x); omin = Math.min(omin, p[other]); omax = Math.max(omax, p[other]); }
  const span = Math.max(xmax * 1.1, (omax - omin) * 1.3 * (W / H));
  const sx = (W - 2 * pad) / span;
  const ox = pad, oy = H / 2 + ((omax + omin) / 2) * sx;
  const X = (x) => ox + x * sx, Y = (o) => oy - o * sx;
  ctx.strokeStyle = "#234"; ctx.lineWidth = 1;
  ctx.beginPath(); ctx.moveTo(X(0), Y(0)); ctx.lineTo(W, Y(0)); ctx.stroke();
  ctx.fillStyle = "#8aa5b3"; ctx.font = "12px system-ui";
  ctx.fillText(`x (m) → ${span.toFixed(1)} m across`, W - 150, H - 8);
  ctx.fillText(other === "y" ? "y ↑" : "z ↑", 4, 14);
  ctx.fillStyle = "#ffd54a"; ctx.font = "20px system-ui";
  ctx.fillText("★", X(0) - 8, Y(0) + 7);
  ctx.lineWidth = 2;
  for (let i = 1; i < pts.length; i++) {
    ctx.strokeStyle = pts[i].ok ? "#3fbf7f" : "#e0a030";
    ctx.beginPath(); ctx.moveTo(X(pts[i - 1].x), Y(pts[i - 1][other])); ctx.lineTo(X(pts[i].x), Y(pts[i][other])); ctx.stroke();
  }
  const last = pts[pts.length - 1];
  if (last) { ctx.fillStyle = "#fff"; ctx.beginPath(); ctx.arc(X(last.x), Y(last[other]), 5, 0, 7); ctx.fill(); }
  canvas.dataset.points = String(pts.length);
}

// --- status ------------------------------------------------------------------

function showStatusWord(word) {
  const el = $("status");
  el.textContent = word;
  el.className = "status " + (word === "ok" ? "ok" : word === "initialising" || word === "unobservable" ? "warn" : "bad");
}

function age(a, limit) {
  if (a === null || a === undefined) return ["never", "never"];
  return [`${a.toFixed(2)} s`, limit !== undefined && a > limit ? "stale" : ""];
}

function rows(id, list) {
  $(id).innerHTML = "";
  for (const [k, v, cls] of list) {
    const tr = document.createElement("tr");
    const th = document.createElement("th"); th.textContent = k;
    const td = document.createElement("td"); td.textContent = v; if (cls) td.className = cls;
    tr.appendChild(th); tr.appendChild(td); $(id).appendChild(tr);
  }
}

// Why the daemon is not well, in words: the pose's status, then the
// source's state and error, then readings gone stale.
function reasons(st) {
  const out = [];
  const word = st.estimator && st.estimator.status;
  if (word && word !== "ok") out.push(`${word}: ${WHY[word] || "see docs/estimators.md"}`);
  const b = st.backend || {};
  if (b.state && b.state !== "running") out.push(`source ${b.state}${b.last_error ? ": " + b.last_error : ""}`);
  const h = b.health || {};
  if (h.injected_faults > 0) out.push(`${h.injected_faults} faults injected by the mock backend so far`);
  if (st.failed > 0) out.push(`${st.failed} frames failed${b.last_error ? " (last: " + b.last_error + ")" : ""}`);
  const ex = (st.channels && st.channels.excluded_now) || [];
  if (ex.length) out.push(`photodiodes left out as stuck: ${ex.map((rc) => `[${rc}]`).join(" ")}`);
  const v = st.vehicle || {};
  if (v.enabled && v.mavlink && v.mavlink.autopilot_heartbeat_age_s === null) out.push("no HEARTBEAT from the autopilot yet");
  return out;
}

function showStatus(st) {
  seen.lastStatus = st;
  const why = reasons(st);
  $("why").hidden = why.length === 0;
  $("why").textContent = why.join(" · ");
  if (st.estimator && seen.lastPose === null) showStatusWord(st.estimator.status);
  const lat = st.latency || {};
  rows("counters", [
    ["frames", `${st.frames} (${fmt(st.fps, 1)} fps)`],
    ["late / failed / lost", `${st.late} / ${st.failed} / ${st.lost}`],
    ["latency p50 / p99", `${fmt(lat.p50 * 1e3, 2)} / ${fmt(lat.p99 * 1e3, 2)} ms`],
    ["source", `${st.backend.kind}: ${st.backend.state}`, st.backend.state === "running" ? "" : "stale"],
    ["recording", st.recording ? st.recording.state : "off"],
    ["uptime", `${fmt(st.uptime, 0)} s`],
  ]);
  const e = st.estimator || {};
  const counts = e.counts ? Object.entries(e.counts).filter(([, n]) => n > 0).map(([k, n]) => `${k} ${n}`).join(", ") : "";
  const d = st.demodulator || {};
  rows("estimator", [
    ["estimator", e.name],
    ["calibration", e.calibration],
    ["reloads", String(e.reloads)],
    ["statuses", counts],
    ["demodulator", d.enabled ? `${d.beacons.filter((b) => b.locked).length} of ${d.beacons.length} beacons locked` : "off (steady beacon)"],
  ]);
  const v = st.vehicle || {};
  const r = v.readings || {};
  const att = st.attitude || {};
  const readingRows = [];
  for (const name of ["attitude", "depth", "velocity", "temperature"]) {
    if (r[name]) {
      const [a, cls] = age(r[name].age_s, 1.0);
      readingRows.push([name === "velocity" ? "DVL" : name, a, cls]);
    }
  }
  if (att.input) { const [a, cls] = age(att.age, 0.5); readingRows.push(["attitude input", a, cls]); }
  if (v.enabled && v.mavlink) { const [a, cls] = age(v.mavlink.autopilot_heartbeat_age_s, 3.0); readingRows.push(["autopilot heartbeat", a, cls]); }
  if (!readingRows.length) readingRows.push(["none configured", att.enabled ? "attitude from the source" : "light only", "never"]);
  rows("readings", readingRows);
  if (v.enabled && v.mavlink) {
    const m = v.mavlink;
    const sent = (m.sent && Object.values(m.sent).reduce((a, b) => a + b, 0)) || 0;
    rows("mavlink", [
      ["connection", v.connection || "—"],
      ["peer", m.peer || "none yet"],
      ["frames in", String(m.frames)],
      ["messages out", String(sent)],
      ["link opens / failures", `${m.link_opens} / ${m.link_failures}`],
    ]);
  } else {
    rows("mavlink", [["link", "not configured ([mavlink])", "never"]]);
  }
}

// --- control ([web] control = true) ---------------------------------------------

let controlShown = false;
function showControl(st) {
  if (st.recording) $("rec-state").textContent = st.recording.state;
  if (!(st.web && st.web.control) || controlShown) return;
  controlShown = true;
  $("control-card").hidden = false;
  $("reload").onclick = () => {
    fetch("v1/reload", { method: "POST" })
      .then((r) => r.json())
      .then((v) => { $("reload-said").textContent = v.error || "asked: STATUS counts the reload"; })
      .catch((e) => { $("reload-said").textContent = String(e); });
  };
  $("cfgfile").onchange = () => {
    const f = $("cfgfile").files[0];
    if (!f) return;
    fetch("v1/check-config", { method: "POST", body: f })
      .then((r) => r.json())
      .then((v) => {
        $("verdict").textContent = v.ok ? v.verdict : v.error;
        $("verdict").className = "verdict " + (v.ok ? "ok" : "bad");
      })
      .catch((e) => { $("verdict").textContent = String(e); });
  };
  for (const [id, what] of [["rec-stop", "stop"], ["rec-start", "start"]]) {
    $(id).onclick = () => fetch(`v1/recording/${what}`, { method: "POST" }).then(() => setTimeout(list, 1500));
  }
  const list = () => fetch("v1/recordings").then((r) => r.json()).then((v) => {
    const t = $("recordings");
    t.innerHTML = "";
    for (const f of v.files || []) {
      const tr = document.createElement("tr");
      const a = document.createElement("a");
      a.href = "v1/recordings/" + encodeURIComponent(f.name);
      a.download = f.name;
      a.textContent = f.name;
      const td1 = document.createElement("td"); td1.appendChild(a);
      const td2 = document.createElement("td"); td2.textContent = `${(f.bytes / 1e6).toFixed(2)} MB`;
      tr.appendChild(td1); tr.appendChild(td2); t.appendChild(tr);
    }
    if (!(v.files || []).length) rows("recordings", [["none", v.error || "no recording in the folder", "never"]]);
  }).catch(() => {});
  list();
  setInterval(list, 5000);
}

// --- the feed ----------------------------------------------------------------

let source = null;
function connect() {
  source = new EventSource("v1/events");
  source.onopen = () => {
    seen.connects += 1;
    $("conn").textContent = "live";
    $("conn").className = "conn ok";
  };
  source.addEventListener("live", (m) => {
    seen.live += 1;
    const ev = JSON.parse(m.data);
    showImage(ev.frame);
    if (ev.pose) showPose(ev.pose, ev.frame);
  });
  source.addEventListener("status", (m) => {
    seen.status += 1;
    const st = JSON.parse(m.data);
    showStatus(st);
    showControl(st);
  });
  source.onerror = () => {
    $("conn").textContent = "reconnecting…";
    $("conn").className = "conn bad";
    // The browser retries by itself after a dropped stream; after an
    // answer that is not a stream (a proxy's 502 while the daemon
    // restarts) it gives up: then start again.
    if (source.readyState === EventSource.CLOSED) {
      source.close();
      setTimeout(connect, 1000);
    }
  };
}

fetch("register_service").then((r) => r.json()).then((s) => { $("version").textContent = s.version; }).catch(() => {});
connect();
