"use strict";
// The clinician's station page: draws the virtual arm from the frames the station sends
// (~60 per second), and sends the clinician's clicks and keys as commands. Positions arrive
// in the shoulder frame (m, +x to the patient's right, +y forward); forces in N on the handle.

const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("token") || "";
const canvas = $("arm");
const ctx = canvas.getContext("2d");

// What tests and the benchmark read: the last frames drawn, where the handle was drawn.
const fb = window.fb = { frames: [], info: null, fps: 0, drawn: 0, last: null, replies: [],
                         paused: false };

let ws = null;
let bands = [];            // muscle bands as drawn (canvas px), for the hover label
const MUSCLES = STATION_CONFIG.muscles || [];
let frame = null;          // newest frame received
let drawnSeq = null;       // seq of the frame last drawn
let info = null;
let infoAt = 0;            // frame t_s when the info arrived
let nextId = 1;
let view = null;           // world -> canvas transform
const pending = new Map();

// --- connection ------------------------------------------------------------------------------
function connect() {
  const proto = location.protocol === "https:" ? "wss:" : "ws:";
  // the station on its own: /ws with the session's token; inside the workspace: the
  // application's own socket, authenticated by its login session
  const path = STATION_CONFIG.ws_path || "/ws";
  ws = new WebSocket(`${proto}//${location.host}${path}?token=${encodeURIComponent(token)}`);
  ws.onopen = () => setMessage("");
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "frame") {
      frame = msg;
    } else if (msg.type === "info") {
      info = msg; fb.info = msg; infoAt = frame ? frame.t_s : (msg.t_s || 0);
      view = null; renderPanel();
    } else if (msg.type === "reply") {
      fb.replies.push(msg);
      const done = pending.get(msg.id);
      pending.delete(msg.id);
      if (!msg.ok) setMessage(msg.error, true);
      if (done) done(msg);
    } else if (window.fbExtra) {
      window.fbExtra.onMessage(msg);  // panels of their own (haptic/remote/desk.js)
    }
  };
  ws.onclose = () => {
    setState("DISCONNECTED", "station connection lost; reconnecting…");
    setTimeout(connect, 1000);
  };
}

function send(cmd, args = {}) {
  return new Promise((resolve) => {
    if (!ws || ws.readyState !== WebSocket.OPEN) {
      setMessage("not connected to the station", true); resolve(null); return;
    }
    const id = nextId++;
    pending.set(id, resolve);
    ws.send(JSON.stringify({ id, cmd, ...args }));
  });
}

window.fbSend = send;

function setMessage(text, error = false) {
  $("message").textContent = text || "";
  $("message").className = "small" + (error ? " error" : "");
}

function setState(mode, text) {
  const el = $("state");
  el.dataset.mode = mode;
  el.textContent = text;
}

// --- drawing -----------------------------------------------------------------------------------
function fitView() {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
  }
  const pts = (info && info.workspace_m && info.workspace_m.length) ? info.workspace_m.slice()
    : [[-0.4, -0.1], [0.6, 0.7]];
  pts.push([0, 0], [trunkX() * 2.2, -0.15]);
  const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
  const x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = Math.min(...ys), y1 = Math.max(...ys);
  const top = 18, margin = 22;  // the badges and the scale live outside the canvas
  const s = Math.min((w - 2 * margin) / (x1 - x0), (h - top - margin) / (y1 - y0));
  // 'opposite': the patient faces the clinician (seed): forward (+y) points down the screen,
  // the patient's right (+x) is the clinician's left. 'behind': as seen over the shoulder.
  const opposite = !STATION_CONFIG.view || STATION_CONFIG.view === "opposite";
  const mx = opposite ? -1 : 1, my = opposite ? 1 : -1;
  const cxw = (x0 + x1) / 2, cyw = (y0 + y1) / 2;
  const cx = w / 2, cy = top + (h - top - margin) / 2;
  view = { s, dpr, px: (x) => cx + mx * s * (x[0] - cxw), py: (x) => cy + my * s * (x[1] - cyw) };
  $("scale-bar").style.width = `${Math.max(4, Math.round(0.1 * s))}px`;  // 10 cm
}

function P(x) { return [view.px(x), view.py(x)]; }
function side() { return info && info.side === "left" ? -1 : 1; }
function trunkX() { return -0.19 * side(); }

function line(a, b, width, color) {
  ctx.lineWidth = width; ctx.strokeStyle = color; ctx.lineCap = "round";
  ctx.beginPath(); ctx.moveTo(...P(a)); ctx.lineTo(...P(b)); ctx.stroke();
}

function disc(x, r, color) {
  ctx.fillStyle = color; ctx.beginPath(); ctx.arc(...P(x), r, 0, 2 * Math.PI); ctx.fill();
}

function drawBody() {
  // the patient's trunk and head seen from above, behind the shoulder
  const c = [trunkX(), -0.07];
  ctx.fillStyle = "#dfe3ea"; ctx.strokeStyle = "#aeb5c2"; ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.ellipse(...P(c), 0.21 * view.s, 0.11 * view.s, 0, 0, 2 * Math.PI);
  ctx.fill(); ctx.stroke();
  ctx.fillStyle = "#e9ecf1";
  ctx.beginPath(); ctx.arc(...P([c[0], -0.06]), 0.085 * view.s, 0, 2 * Math.PI);
  ctx.fill(); ctx.stroke();
}

function drawWorkspace() {
  if (info && info.safety_box_m) {
    const [a, b, c, d] = info.safety_box_m;
    ctx.setLineDash([6, 6]); ctx.strokeStyle = "#b9c0cc"; ctx.lineWidth = 1.5;
    ctx.beginPath();
    [[a, c], [b, c], [b, d], [a, d]].forEach((p, i) => (i ? ctx.lineTo(...P(p)) : ctx.moveTo(...P(p))));
    ctx.closePath(); ctx.stroke(); ctx.setLineDash([]);
  }
  const ws = info && info.workspace_m;
  if (!ws || !ws.length) return;
  ctx.fillStyle = "rgba(47,111,179,0.07)"; ctx.strokeStyle = "rgba(47,111,179,0.45)";
  ctx.lineWidth = 1.5; ctx.beginPath();
  ws.forEach((p, i) => (i ? ctx.lineTo(...P(p)) : ctx.moveTo(...P(p))));
  ctx.closePath(); ctx.fill(); ctx.stroke();
}

function drawPaths() {
  const tr = info && info.training;
  const paths = (tr && tr.paths) || [];
  const colours = ["#7b3fb0", "#138d75", "#a04000", "#1f618d"];
  paths.forEach((p, k) => {
    const col = colours[k % colours.length], pts = p.points_m;
    if (!pts || pts.length < 2) return;
    ctx.setLineDash([10, 7]); ctx.lineWidth = 4; ctx.strokeStyle = col; ctx.beginPath();
    pts.forEach((q, i) => (i ? ctx.lineTo(...P(q)) : ctx.moveTo(...P(q))));
    ctx.stroke(); ctx.setLineDash([]);
    const [ex, ey] = P(pts[pts.length - 1]), [fx, fy] = P(pts[pts.length - 2]);
    const a = Math.atan2(ey - fy, ex - fx);
    ctx.fillStyle = col; ctx.beginPath(); ctx.moveTo(ex, ey);
    ctx.lineTo(ex - 16 * Math.cos(a - 0.4), ey - 16 * Math.sin(a - 0.4));
    ctx.lineTo(ex - 16 * Math.cos(a + 0.4), ey - 16 * Math.sin(a + 0.4)); ctx.fill();
    // labels stacked beside the common start, so paths that share it do not overwrite them
    const [sx, sy] = P(pts[0]);
    ctx.font = "600 15px system-ui"; ctx.textAlign = "right";
    ctx.fillText(`${k + 1}. ${p.name}`, sx - 24, sy - 10 + 18 * k);
    ctx.textAlign = "left";
    disc(pts[0], 5, col);
  });
}

// muscle groups (sf, se, ef, ee, bf, be) as bands beside the bones, flexors on the side the
// joint flexes toward; each is a quadratic curve from origin to insertion, bowed at the joint
function muscleCurves(f) {
  const e = f.elbow_m, h = f.hand_m, sd = side();
  const unit = (a, b) => { const dx = b[0] - a[0], dy = b[1] - a[1], n = Math.hypot(dx, dy) || 1;
    return [dx / n, dy / n]; };
  const u1 = unit([0, 0], e), u2 = unit(e, h);
  const n1 = [-u1[1] * sd, u1[0] * sd], n2 = [-u2[1] * sd, u2[0] * sd];
  const at = (o, u, n, a, b) => [o[0] + a * u[0] + b * n[0], o[1] + a * u[1] + b * n[1]];
  const l1 = Math.hypot(e[0], e[1]), l2 = Math.hypot(h[0] - e[0], h[1] - e[1]);
  const mid = (a, b, k) => [(a[0] + b[0]) / 2 + k[0], (a[1] + b[1]) / 2 + k[1]];
  const out = [];
  for (const sg of [1, -1]) {
    const sh = [at([0, 0], u1, n1, -0.04, sg * 0.035), at([0, 0], u1, n1, 0.4 * l1, sg * 0.024)];
    const el = [at(e, u1, n1, -0.5 * l1, sg * 0.024), at(e, u2, n2, 0.28 * l2, sg * 0.022)];
    const bi = [at([0, 0], u1, n1, 0.05, sg * 0.042), at(e, u2, n2, 0.2 * l2, sg * 0.04)];
    const ej = [sg * (n1[0] + n2[0]) * 0.02, sg * (n1[1] + n2[1]) * 0.02];
    out.push([sh[0], mid(sh[0], sh[1], [0, 0]), sh[1]],
             [el[0], at(e, n1, n1, 0, sg * 0.03), el[1]],
             [bi[0], [e[0] + ej[0] * 2.6, e[1] + ej[1] * 2.6], bi[1]]);
  }
  // order sf, se, ef, ee, bf, be
  return [out[0], out[3], out[1], out[4], out[2], out[5]];
}

// One colour per muscle group (sf, se, ef, ee, bf, be: Okabe & Ito's palette, told apart with
// every common colour-vision deficiency); the band's width and strength say its force.
const MUSCLE_COLOURS = ["#E69F00", "#56B4E9", "#009E73", "#0072B2", "#D55E00", "#CC79A7"];
const FULL_FORCE_N = 40;  // a band this strong is drawn widest and opaque

function tension(n) { return Math.max(0, Math.min(1, n / FULL_FORCE_N)); }

function muscleStyle(i, n) {
  const t = tension(n);
  return { colour: MUSCLE_COLOURS[i % MUSCLE_COLOURS.length], alpha: 0.6 + 0.4 * t,
           width: 4 + 10 * t };
}

function drawArm(f) {
  const S = [0, 0], E = f.elbow_m, H = f.hand_m;
  if (f.muscles_n) {
    ctx.lineCap = "round";
    bands = [];
    muscleCurves(f).forEach(([a, c, b], i) => {
      const st = muscleStyle(i, f.muscles_n[i]);
      ctx.globalAlpha = st.alpha; ctx.lineWidth = st.width; ctx.strokeStyle = st.colour;
      ctx.beginPath(); ctx.moveTo(...P(a)); ctx.quadraticCurveTo(...P(c), ...P(b)); ctx.stroke();
      ctx.globalAlpha = 1;
      // points along the band, for the hover label
      const pa = P(a), pc = P(c), pb = P(b), pts = [];
      for (let k = 0; k <= 12; k++) {
        const t = k / 12, u = 1 - t;
        pts.push([u * u * pa[0] + 2 * u * t * pc[0] + t * t * pb[0],
                  u * u * pa[1] + 2 * u * t * pc[1] + t * t * pb[1]]);
      }
      bands.push(pts);
    });
  } else {
    bands = [];
  }
  line(S, E, 0.045 * view.s, "#6b7385");
  line(E, H, 0.038 * view.s, "#6b7385");
  disc(S, 0.03 * view.s, "#4a5263");
  disc(E, 0.024 * view.s, "#4a5263");
  disc(H, 0.03 * view.s, "#39404f");
}

const HANDLE_R = 15;  // px: the handle's ring

function drawHandle(f) {
  // the handle (robot) the hand holds: a dark ring with a yellow centre, over the arm
  const [hx, hy] = P(f.handle_m);
  ctx.lineWidth = 4; ctx.strokeStyle = "#1d2330";
  ctx.beginPath(); ctx.arc(hx, hy, HANDLE_R, 0, 2 * Math.PI); ctx.stroke();
  ctx.fillStyle = "#F0E442"; ctx.beginPath(); ctx.arc(hx, hy, 6, 0, 2 * Math.PI); ctx.fill();
  return [hx, hy];
}

function drawForce(f) {
  // the force on the handle as an arrow from the ring's edge, drawn over the handle, so a
  // small force is seen too: 10 N is 6 cm beyond the ring, and a short stub shows any force
  const [fx, fy] = f.force_n, n = Math.hypot(fx, fy);
  const mPerN = 0.006, stub = 10;
  const [ax, ay] = P(f.handle_m);
  const [tx, ty] = P([f.handle_m[0] + fx, f.handle_m[1] + fy]);
  const ang = Math.atan2(ty - ay, tx - ax);
  const len = stub + mPerN * n * view.s;
  const sx = ax + (HANDLE_R + 3) * Math.cos(ang), sy = ay + (HANDLE_R + 3) * Math.sin(ang);
  const bx = sx + len * Math.cos(ang), by = sy + len * Math.sin(ang);
  if (n > 0.05) {
    ctx.lineCap = "round";
    for (const [w, c] of [[8, "#ffffff"], [4, "#1d2330"]]) {  // a white edge: seen on any band
      ctx.lineWidth = w; ctx.strokeStyle = c;
      ctx.beginPath(); ctx.moveTo(sx, sy); ctx.lineTo(bx, by); ctx.stroke();
    }
    ctx.fillStyle = "#1d2330"; ctx.beginPath();
    ctx.moveTo(bx + 6 * Math.cos(ang), by + 6 * Math.sin(ang));
    ctx.lineTo(bx - 12 * Math.cos(ang - 0.5), by - 12 * Math.sin(ang - 0.5));
    ctx.lineTo(bx - 12 * Math.cos(ang + 0.5), by - 12 * Math.sin(ang + 0.5)); ctx.fill();
  }
  ctx.font = "700 16px system-ui"; ctx.fillStyle = "#1d2330";
  ctx.fillText(`${n.toFixed(1)} N`, Math.max(bx, ax + HANDLE_R) + 12, Math.max(by, ay) + 5);
}

let fpsCount = 0, fpsT0 = performance.now();

function draw() {
  requestAnimationFrame(draw);
  if (!frame || !info) return;
  const dpr = window.devicePixelRatio || 1;
  if (!view || canvas.width !== Math.round(canvas.clientWidth * dpr)
      || canvas.height !== Math.round(canvas.clientHeight * dpr)) {
    fitView();  // also when the fault box or the legend changes the canvas's height
  }
  const f = frame;
  ctx.setTransform(view.dpr, 0, 0, view.dpr, 0, 0);
  ctx.clearRect(0, 0, canvas.clientWidth, canvas.clientHeight);
  drawWorkspace();
  drawBody();
  drawPaths();
  if (window.fbExtra) window.fbExtra.draw(ctx, P, view);
  drawArm(f);
  const [px, py] = drawHandle(f);
  drawForce(f);  // over the handle: a small force is not hidden under its ring
  if (f.seq !== drawnSeq) {
    drawnSeq = f.seq; fpsCount++; fb.drawn++;
    fb.last = { t_s: f.t_s, x: f.handle_m[0], y: f.handle_m[1], px, py };
    fb.frames.push(fb.last);
    if (fb.frames.length > 600) fb.frames.shift();
  }
  const now = performance.now();
  if (now - fpsT0 >= 1000) {
    fb.fps = fpsCount * 1000 / (now - fpsT0); fpsCount = 0; fpsT0 = now;
    $("fps").textContent = `${fb.fps.toFixed(0)} frames/s · t = ${f.t_s.toFixed(1)} s`;
    if (ws && ws.readyState === WebSocket.OPEN) {
      ws.send(JSON.stringify({ cmd: "page_stats", fps: fb.fps }));
    }
  }
  updateBadges(f);
  updateMuscleLegend(f);
  updateFault(f);
  tickClock(f);
}

function updateBadges(f) {
  const faults = f.faults.length ? ` · ${f.faults.join(", ")}` : "";
  const words = { ARMED: "Armed", DISARMED: "Disarmed", FAULT: "Fault" };
  setState(f.mode, `${words[f.mode] || f.mode}${faults}`);
  const r = $("rendering");
  const tr = info && info.training;
  if (window.fbExtra && window.fbExtra.badge(f)) {
    // the panel's own badge (haptic/remote/desk.js)
  } else if (tr && !tr.done && !f.blinded) {
    r.textContent = tr.phase ? `Training · ${tr.phase}` : "Training"; r.className = "badge";
    $("btn-a").classList.remove("active"); $("btn-b").classList.remove("active");
  } else if (f.blinded) {
    r.textContent = "Blinded: which arm is hidden"; r.className = "badge blinded";
  } else {
    const k = f.blend >= 0.5 ? "B" : "A";
    const moving = f.blend > 0.02 && f.blend < 0.98 ? " (crossfading)" : "";
    const which = `${k} · ${k === "A" ? "before" : "after"}`;
    r.textContent = f.mode === "ARMED" ? `Feeling ${which}${moving}`
      : `${which} selected · no force while ${f.mode === "FAULT" ? "in fault" : "disarmed"}`;
    r.className = "badge";
    $("btn-a").classList.toggle("active", k === "A");
    $("btn-b").classList.toggle("active", k === "B");
  }
}

// --- muscle legend, hover, fault box -----------------------------------------------------------
function buildMuscleLegend() {
  $("muscle-legend").innerHTML = MUSCLES.map((m, i) =>
    `<span class="m" data-i="${i}" title="${esc(m.name)}"><span class="sw"></span>` +
    `<b>${esc(m.code)}</b> ${esc(m.name)}<span class="mf"></span></span>`).join("") +
    `<span class="m">band width: the group's force, 0 → ${FULL_FORCE_N} N</span>`;
}

function updateMuscleLegend(f) {
  document.querySelectorAll("#muscle-legend .m[data-i]").forEach((el) => {
    const i = Number(el.dataset.i), n = f.muscles_n ? f.muscles_n[i] : null;
    el.querySelector(".sw").style.background = MUSCLE_COLOURS[i % MUSCLE_COLOURS.length];
    el.querySelector(".mf").textContent = n === null ? "" : ` ${n.toFixed(0)} N`;
  });
}

canvas.addEventListener("mousemove", (ev) => {
  const r = canvas.getBoundingClientRect(), x = ev.clientX - r.left, y = ev.clientY - r.top;
  let best = -1, dist = 14;
  bands.forEach((pts, i) => pts.forEach(([px, py]) => {
    const d = Math.hypot(px - x, py - y);
    if (d < dist) { dist = d; best = i; }
  }));
  const tip = $("tip");
  if (best < 0 || !MUSCLES[best]) { tip.hidden = true; return; }
  const n = frame && frame.muscles_n ? ` · ${frame.muscles_n[best].toFixed(1)} N` : "";
  tip.textContent = `${MUSCLES[best].code} · ${MUSCLES[best].name}${n}`;
  tip.style.left = `${x + 14}px`; tip.style.top = `${y + 10}px`; tip.hidden = false;
});
canvas.addEventListener("mouseleave", () => { $("tip").hidden = true; });

let faultShown = "";

function updateFault(f) {
  const box = $("fault"), faults = (info && info.faults_now) || [];
  const on = f.mode === "FAULT";
  box.hidden = !on;
  fb.paused = on || f.mode === "DISARMED";
  document.querySelectorAll(".paused-note").forEach((el) => { el.hidden = !fb.paused; });
  document.querySelectorAll(".train-answer, .abx-answer, .abx-present").forEach((b) => {
    b.disabled = fb.paused;
  });
  if ($("train-next")) $("train-next").disabled = fb.paused || !!(info && info.training && info.training.awaiting_answer);
  if (!on) { faultShown = ""; return; }
  const key = JSON.stringify([faults, info && info.rearm_refused_because, info && info.paused]);
  if (key === faultShown) return;
  faultShown = key;
  $("fault-title").textContent = faults.length
    ? `Fault: ${faults.map((x) => x.name).join(", ")} · force is zero`
    : `Fault: ${f.faults.join(", ")} · force is zero`;
  $("fault-list").innerHTML = faults.map((x) =>
    `<p>${esc(x.what)} <span class="small">(${esc(x.message)}, at ${x.t_s.toFixed(1)} s)</span></p>` +
    `<p class="todo">${esc(x.todo)}</p>`).join("");
  $("fault-paused").hidden = !(info && info.paused);
  const why = (info && info.rearm_refused_because) || [];
  $("rearm-why").textContent = why.length ? `Re-arm will be refused now: ${why.join("; ")}.`
    : "Re-arm re-runs every safety check; output ramps back in over 0.3 s.";
}

function rearm() {
  send("arm").then((r) => {
    if (r && !r.ok) $("rearm-why").textContent = r.error;
  });
}

// --- the panel ------------------------------------------------------------------------------
const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[c]));
const pct = (v) => (v === null || v === undefined ? "–" : `${Math.round(100 * v)}%`);

function describe(m) {
  return m ? esc(m.text || m.label || "not described") : "";
}

function renderPanel() {
  const hidden = info.models === "hidden";
  $("model-info").innerHTML = hidden
    ? "<dt>Models</dt><dd>hidden while a blinded block runs</dd>"
    : `<dt>A · before</dt><dd>${describe(info.models.A)}</dd>` +
      `<dt>B · after</dt><dd>${describe(info.models.B)}</dd>`;
  const abx = info.abx, tr = info.training;
  const training = tr && !tr.done;
  $("btn-a").disabled = $("btn-b").disabled = !!abx || !!training;
  $("abx-idle").hidden = !!abx;
  $("abx-start").disabled = !!training;
  $("abx-run").hidden = !abx;
  if (abx) $("abx-trial").textContent = `Trial ${Math.min(abx.trial + 1, abx.n_trials)} of ${abx.n_trials}: feel A, B and X as often as you like, then answer.`;
  $("abx-result").innerHTML = info.abx_last_result && !abx ? abxResult(info.abx_last_result) : "";
  // training
  const proto = training ? { name: tr.protocol, n_trials: tr.n_trials } : (STATION_CONFIG.training || {});
  $("protocol-name").textContent = proto.name ? `${proto.name} protocol · ${proto.n_trials} trials` : "";
  $("train-idle").hidden = training;
  $("train-start").disabled = !!abx;
  $("train-run").hidden = !training;
  $("train-result").innerHTML = tr && tr.done && tr.result ? trainingResult(tr.result.summary, tr) : "";
  // shading through the CSSOM: the page's policy allows no style attributes in markup
  document.querySelectorAll("[data-shade]").forEach((td) => {
    td.style.background = `rgba(47,111,179,${td.dataset.shade})`;
  });
  const legend = $("legend");
  if (training && tr.legend) {
    legend.hidden = false;
    legend.innerHTML = `${esc(tr.legend)}<small>familiarisation · trial ${tr.trial} of ${tr.n_trials}</small>`;
  } else {
    legend.hidden = true;
  }
  if (training) {
    const phase = tr.phase === "assessment" ? "Assessment" : tr.phase === "familiarisation" ? "Familiarisation" : "Ready";
    const which = tr.trial ? `trial ${tr.trial} of ${tr.n_trials}` : `${tr.n_trials} trials`;
    const instr = tr.instruction === "instructed" ? "follow the drawn paths" : "explore freely";
    $("train-trial").textContent = `${phase}: ${which} (${instr}).` +
      (tr.phase === "assessment" ? " Which muscles are hypertonic?" : "") +
      (!tr.trial ? " Press Next trial to begin." : "");
    $("train-answers").hidden = !tr.awaiting_answer;
    $("train-auto").parentElement.hidden = tr.phase === "assessment";
    $("train-next").disabled = tr.awaiting_answer || !!fb.paused;
  }
}

function abxResult(r) {
  const rows = r.answers.map((a) => `<tr><td>${a.trial + 1}</td><td>${a.answer}</td>` +
    `<td>${a.x_was || (a.x_model === 0 ? "before" : "after")}</td>` +
    `<td>${a.flagged ? "flagged" : (a.correct ? "✓" : "✗")}</td></tr>`).join("");
  const counted = r.counted === undefined ? r.answered : r.counted;
  const flagged = r.flagged ? ` · ${r.flagged} flagged (a fault or no force) and left out` : "";
  return `<p class="result-title">Block: ${r.correct} of ${counted} counted answers correct${flagged}</p>` +
    `<table><tr><th>trial</th><th>answer</th><th>X was</th><th></th></tr>${rows}</table>` +
    '<p class="small">A is the model before, B the model after; X was one of them.</p>';
}

function trainingResult(s, tr) {
  const conf = s.confusion, names = { shoulder: "shoulder", elbow: "elbow", biarticular: "bi-articular" };
  const head = conf.columns.map((c) => `<th>${names[c === "both" ? "biarticular" : c] || c}</th>`).join("");
  const rows = conf.rows.map((g, i) => {
    const n = conf.counts[i].reduce((a, b) => a + b, 0);
    const cells = conf.counts[i].map((k, j) => {
      const diag = ({ shoulder: 0, elbow: 1, biarticular: 2 })[g] === j;
      const a = n ? k / n : 0;
      return `<td class="${diag ? "diag" : ""}" data-shade="${(k ? 0.08 + 0.6 * a : 0).toFixed(2)}">${k}</td>`;
    }).join("");
    return `<tr><th>${names[g] || g}</th>${cells}</tr>`;
  }).join("");
  const sev = Object.entries(s.by_severity).map(([k, v]) =>
    `<tr><th>${k}</th><td>${v.correct} / ${v.n}</td><td>${pct(v.accuracy)}</td></tr>`).join("");
  const flagged = s.flagged ? `<p class="small">${s.flagged} answered trial(s) (${s.flagged_trials.join(", ")}) flagged - a fault or no force during the trial - and left out.</p>` : "";
  return `<p class="result-title">${tr.abandoned ? "Stopped early: " : ""}${s.accuracy.correct} of ${s.accuracy.n} correct (${pct(s.accuracy.accuracy)}, chance ${pct(s.chance)})</p>` + flagged +
    `<table><tr><th>true \\ answer</th>${head}</tr>${rows}</table>` +
    `<table><tr><th>severity</th><th>correct</th><th>accuracy</th></tr>${sev}</table>`;
}

let autoNextSent = null;

function tickClock(f) {
  const tr = info && info.training;
  const el = $("train-clock");
  if (!tr || tr.done || !tr.trial || tr.elapsed_s === null || tr.elapsed_s === undefined) {
    el.textContent = ""; return;
  }
  const left = tr.duration_s - (tr.elapsed_s + (f.t_s - (info.t_s || infoAt)));
  el.textContent = left > 0 ? `${left.toFixed(0)} s` : (tr.awaiting_answer ? "time is up: answer" : "time is up");
  el.classList.toggle("up", left <= 0);
  if (left <= 0 && tr.phase === "familiarisation" && $("train-auto").checked && !fb.paused &&
      autoNextSent !== tr.trial) {
    autoNextSent = tr.trial;
    send("train", { action: "next" });
  }
}

// --- controls -------------------------------------------------------------------------------
function switchTo(k) { if (info && !info.abx && !(info.training && !info.training.done)) send("switch", { to: k }); }
$("btn-a").onclick = () => switchTo("A");
$("btn-b").onclick = () => switchTo("B");
$("abx-start").onclick = () => send("abx", { action: "start", n_trials: Math.max(1, Math.min(100, parseInt($("abx-n").value, 10) || 10)) });
document.querySelectorAll(".abx-present").forEach((b) => { b.onclick = () => send("abx", { action: "present", label: b.dataset.label }); });
document.querySelectorAll(".abx-answer").forEach((b) => { b.onclick = () => send("abx", { action: "answer", answer: b.dataset.answer }); });
$("train-start").onclick = () => send("train", { action: "start", instruction: $("train-instruction").value })
  .then((r) => { if (r && r.ok) send("train", { action: "next" }); });
$("train-next").onclick = () => send("train", { action: "next" });
$("train-stop").onclick = () => send("train", { action: "stop" });
document.querySelectorAll(".train-answer").forEach((b) => { b.onclick = () => send("train", { action: "answer", answer: b.dataset.answer }); });
$("btn-arm").onclick = rearm;
$("btn-rearm").onclick = rearm;
$("btn-disarm").onclick = () => send("disarm");

document.addEventListener("keydown", (ev) => {
  if (ev.target && (ev.target.tagName === "INPUT" || ev.target.tagName === "SELECT")) return;
  if (!info) return;
  const k = ev.key.toLowerCase();
  const tr = info.training, training = tr && !tr.done;
  if (info.abx) {
    if (k === "a" || k === "b" || k === "x") send("abx", { action: "present", label: k.toUpperCase() });
  } else if (training) {
    const ans = { 1: "shoulder", 2: "elbow", 3: "both" }[k];
    if (ans && tr.awaiting_answer) send("train", { action: "answer", answer: ans });
    if ((k === "n" || k === "enter") && !tr.awaiting_answer) send("train", { action: "next" });
  } else if (k === "a" || k === "b") {
    switchTo(k.toUpperCase());
  } else if (k === " ") {
    ev.preventDefault();
    switchTo(frame && frame.blend >= 0.5 ? "A" : "B");
  }
});

window.addEventListener("resize", () => { view = null; });
buildMuscleLegend();
connect();
requestAnimationFrame(draw);
