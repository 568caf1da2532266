// The remote assessment's panels (served only when the session is remote): the link's figures
// with the delay each judgement tolerates, and the supervised assessment - the classifier's
// posterior over group x severity after each probe, the clinician's prior, the next probe drawn
// on the arm, and the clinician's own answer. Talks to station.js through window.fbExtra.
"use strict";
(() => {
  if (!STATION_CONFIG.remote) return;
  const $ = (id) => document.getElementById(id);
  const GROUP_WORD = { shoulder: "Shoulder", elbow: "Elbow", biarticular: "Bi-articular",
                       unimpaired: "Unimpaired" };
  const fbr = window.fbRemote = { link: null, posterior: null, answers: [] };
  let link = null, post = null;

  // --- the panel's sections, after the robot's -------------------------------------------
  for (const id of ["models-section", "abx-section", "training-section"]) {
    const el = $(id); if (el) el.hidden = true;
  }
  const panel = $("panel");
  const linkSec = document.createElement("section");
  linkSec.id = "link-section";
  linkSec.innerHTML = `
    <h2>Link <span class="hint">remote patient</span></h2>
    <div id="link-state" class="link-state">waiting for the link…</div>
    <div class="link-figs">
      <div><span class="big" id="link-delay">–</span><span class="unit">ms one-way</span></div>
      <div><span class="big" id="link-loss">–</span><span class="unit">lost</span></div>
      <div><span class="big" id="link-pc">–</span><span class="unit">passivity</span></div>
    </div>
    <canvas id="link-plot" width="300" height="90" aria-label="delay, loss and passivity controller over the last 30 s"></canvas>
    <div id="link-warning" class="link-warning" hidden></div>
    <details><summary class="small">delay each judgement tolerates</summary>
      <table id="link-tolerance"></table></details>`;
  const assessSec = document.createElement("section");
  assessSec.id = "assess-section";
  assessSec.innerHTML = `
    <h2>Assessment <span class="hint">classifier beside you</span></h2>
    <details id="prior-box"><summary>Prior: the impairments you suspect</summary>
      <div id="prior-groups" class="row"></div>
      <div id="prior-levels" class="row"></div>
      <label class="small"><input type="checkbox" id="prior-unimpaired" checked> unimpaired</label>
      <div class="row"><button id="prior-apply">Apply prior</button></div>
    </details>
    <p id="posterior-status" class="small">Probe the arm: each movement from rest to rest is a probe.</p>
    <div id="posterior-best" class="posterior-best" hidden>
      <span id="posterior-group"></span> <span class="p" id="posterior-group-p"></span>
      <div class="small" id="posterior-level"></div>
    </div>
    <table id="posterior-matrix" hidden></table>
    <ol id="posterior-history" class="small"></ol>
    <p id="posterior-next" class="small"></p>
    <p id="posterior-explains" class="small error" hidden></p>
    <div class="answer-box">
      <div class="row">
        <select id="answer-group" aria-label="your answer: group"></select>
        <select id="answer-level" aria-label="your answer: severity"></select>
      </div>
      <input id="answer-note" type="text" maxlength="500" placeholder="note (optional)">
      <div class="row"><button id="answer-save">Save my answer</button>
        <span id="answer-saved" class="small"></span></div>
    </div>`;
  // the assessment first (the clinician's task), the link under it, the robot's buttons last
  const robot = $("robot-section");
  panel.insertBefore(assessSec, robot);
  panel.insertBefore(linkSec, robot);

  function fmtP(p) { return p >= 0.995 ? "> 0.99" : p.toFixed(2); }
  function pIs(p) { return p >= 0.995 ? "p > 0.99" : `p = ${p.toFixed(2)}`; }
  const LEVEL_SHORT = { "very mild": "v. mild", moderate: "mod.", unimpaired: "none" };
  const GROUP_SHORT = { shoulder: "Shoulder", elbow: "Elbow", biarticular: "Bi-articular" };
  // how the far site is re-armed, in words: its fault latches there and only there
  const REARM_FAR = "Patient's robot: fault, force zero. To re-arm, at the patient's side: " +
    "free the patient's arm, check the robot shows no fault of its own, then start the " +
    "patient's site again ('fieldbank haptic remote patient …'); this site then reconnects " +
    "when started again";
  const history = [];

  // --- link --------------------------------------------------------------------------------
  function renderLink(m) {
    link = m; fbr.link = m;
    $("link-delay").textContent = m.one_way_ms == null ? "–" : m.one_way_ms.toFixed(0);
    $("link-loss").textContent = `${(100 * m.loss).toFixed(1)} %`;
    $("link-pc").textContent = `${(100 * m.controller_share).toFixed(0)} %`;
    const st = $("link-state");
    let text, cls;
    if (!m.link_ok) { text = "Link lost: force ramped to zero"; cls = "bad"; }
    else if (m.patient_fault) { text = REARM_FAR; cls = "bad"; }
    else if (m.engaged && m.patient_engaged) { text = "Linked: feeling the patient"; cls = "ok"; }
    else { text = "Link up, not engaged (arm the robot)"; cls = "warn"; }
    st.textContent = `${text} · ${m.dissipated_j.toFixed(3)} J dissipated`;
    st.className = `link-state ${cls}`;
    const w = $("link-warning");
    const ws = m.warnings || [];
    w.hidden = !ws.length;
    const first = ws.find((x) => x.at_hand);
    const rest = ws.filter((x) => !x.at_hand);
    w.innerHTML = (first ? `<div class="at-hand"><b>${first.judgement}</b> (the judgement at hand): the delay, ${(m.one_way_ms || 0).toFixed(0)} ms, is over ${first.limit_ms.toFixed(0)} ms — ${first.why} <span class="small">(${first.source})</span></div>` : "") +
      (rest.length ? `<div class="small">Also beyond what it tolerates: ${rest.map((x) => `${x.judgement.split(" (")[0]} (${x.limit_ms.toFixed(0)} ms, ${x.source})`).join("; ")}.</div>` : "");
    $("link-tolerance").innerHTML = "<tr><th>judgement</th><th>ms</th><th>source</th></tr>" +
      (m.tolerances || []).map((t) => `<tr><td>${t.judgement}</td><td>${t.limit_ms.toFixed(0)}</td><td>${t.source}</td></tr>`).join("");
    plotLink(m.history || []);
  }

  function plotLink(h) {
    const c = $("link-plot"), g = c.getContext("2d");
    const W = c.width, H = c.height;
    g.clearRect(0, 0, W, H);
    g.font = "10px system-ui"; g.fillStyle = "#5d6678";
    if (h.length < 2) { g.fillText("history appears after a few seconds", 6, 14); return; }
    const t0 = h[0].t_s, t1 = h[h.length - 1].t_s || t0 + 1;
    const dmax = Math.max(20, ...h.map((p) => p.one_way_ms || 0)) * 1.15;
    const X = (t) => 30 + (W - 36) * (t - t0) / Math.max(1e-6, t1 - t0);
    const series = [["one_way_ms", dmax, "#2f6fb3", "delay"], ["loss", 0.2, "#b8860b", "loss ×5"],
                    ["controller_share", 1, "#1f8a4c", "passivity"]];
    g.strokeStyle = "#c9ced8"; g.beginPath(); g.moveTo(30, H - 14); g.lineTo(W - 6, H - 14); g.stroke();
    series.forEach(([k, top, col, label], i) => {
      g.strokeStyle = col; g.lineWidth = 1.5; g.beginPath();
      h.forEach((p, j) => {
        const v = p[k] == null ? 0 : p[k];
        const y = H - 14 - (H - 24) * Math.min(1, v / top);
        if (j) g.lineTo(X(p.t_s), y); else g.moveTo(X(p.t_s), y);
      });
      g.stroke();
      g.fillStyle = col; g.fillText(label, 40 + i * 70, 10);
    });
    g.fillStyle = "#5d6678";
    g.fillText(`${dmax.toFixed(0)}`, 2, 16); g.fillText("0", 2, H - 12);
    g.fillText(`last ${(t1 - t0).toFixed(0)} s`, W - 58, H - 2);
  }

  // --- posterior ---------------------------------------------------------------------------
  function renderPosterior(m) {
    if (m.error) { $("posterior-status").textContent = `classification failed: ${m.error}`; return; }
    post = m; fbr.posterior = m;
    $("posterior-status").textContent = `after probe ${m.probe} of ${m.probes} (` +
      `${m.started_s.toFixed(1)}–${m.ended_s.toFixed(1)} s)`;
    $("posterior-best").hidden = false;
    $("posterior-group").textContent = GROUP_WORD[m.group] || m.group;
    $("posterior-group").dataset.group = m.group;
    $("posterior-group-p").textContent = pIs(m.group_probability);
    $("posterior-group-p").dataset.p = String(m.group_probability);
    $("posterior-level").textContent = m.level ? `severity: ${m.level} (${pIs(m.level_probability)})` +
      ` · judgement at hand: ${m.judgement_at_hand}` : "";
    const t = $("posterior-matrix"); t.hidden = false;
    let html = "<tr><th></th>" + m.levels.map((l) => `<th>${LEVEL_SHORT[l] || l}</th>`).join("") + "<th>group</th></tr>";
    for (const g of m.groups) {
      html += `<tr><th>${GROUP_SHORT[g] || g}</th>`;
      for (const l of m.levels) {
        const p = (m.cells[g] || {})[l] || 0;
        html += `<td style="background: rgba(47,111,179,${Math.min(1, p).toFixed(3)}); color: ${p > 0.5 ? "#fff" : "inherit"}">${p < 0.005 ? "" : fmtP(p)}</td>`;
      }
      html += `<td class="diag">${fmtP(m.group_posterior[g] || 0)}</td></tr>`;
    }
    if (m.unimpaired > 0.0005) html += `<tr><th>Unimpaired</th><td colspan="${m.levels.length}"></td><td class="diag">${fmtP(m.unimpaired)}</td></tr>`;
    t.innerHTML = html;
    const h = history.findIndex((x) => x.probe === m.probe);
    const item = { probe: m.probe, text: `${GROUP_WORD[m.group] || m.group}, ${pIs(m.group_probability)}; ${m.level || ""}` };
    if (h >= 0) history[h] = item; else history.push(item);
    $("posterior-history").innerHTML = history.map((x) => `<li>after probe ${x.probe}: ${x.text}</li>`).join("");
    $("posterior-next").textContent = m.next_probe
      ? `Next probe (drawn in green): ${m.next_probe.description}` : `No next probe: ${m.next_reason}`;
    const ex = $("posterior-explains");
    ex.hidden = !!m.explains;
    ex.textContent = m.explains ? "" : "None of the candidates explains the recording well: " +
      "the answer rests on the list of candidates.";
  }

  // --- prior and answer ------------------------------------------------------------------
  function fillChoices(groups, levels) {
    if ($("prior-groups").childElementCount) return;
    $("prior-groups").innerHTML = groups.map((g) => `<label><input type="checkbox" data-g="${g}" checked> ${GROUP_WORD[g] || g}</label>`).join(" ");
    $("prior-levels").innerHTML = levels.map((l) => `<label><input type="checkbox" data-l="${l}" checked> ${l}</label>`).join(" ");
    $("answer-group").innerHTML = `<option value="">group…</option>` +
      [...groups, "unimpaired"].map((g) => `<option value="${g}">${GROUP_WORD[g] || g}</option>`).join("");
    $("answer-level").innerHTML = `<option value="">severity…</option>` +
      levels.map((l) => `<option value="${l}">${l}</option>`).join("");
  }

  $("prior-apply").addEventListener("click", async () => {
    const groups = [...document.querySelectorAll("#prior-groups input:checked")].map((e) => e.dataset.g);
    const levels = [...document.querySelectorAll("#prior-levels input:checked")].map((e) => e.dataset.l);
    await window.fbSend("prior", { groups, levels, unimpaired: $("prior-unimpaired").checked });
  });
  $("answer-save").addEventListener("click", async () => {
    const group = $("answer-group").value || null, level = $("answer-level").value || null;
    const r = await window.fbSend("assess_answer", { group, level, note: $("answer-note").value });
    if (r && r.ok) {
      fbr.answers.push(r.result);
      $("answer-saved").textContent = `saved after probe ${r.result.after_probe}`;
    }
  });

  // --- the next probe on the arm -----------------------------------------------------------
  function drawNext(ctx, P, view) {
    const n = post && post.next_probe;
    if (!n || !n.points_m || n.points_m.length < 2) return;
    ctx.save();
    ctx.strokeStyle = "#1f8a4c"; ctx.lineWidth = 4; ctx.setLineDash([10, 6]);
    ctx.beginPath();
    n.points_m.forEach((p, i) => { const [x, y] = P(p); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
    ctx.stroke(); ctx.setLineDash([]);
    const [sx, sy] = P(n.points_m[0]);
    ctx.fillStyle = "#1f8a4c"; ctx.beginPath(); ctx.arc(sx, sy, 7, 0, 2 * Math.PI); ctx.fill();
    const m = n.points_m.length, [ax, ay] = P(n.points_m[m - 2]), [bx, by] = P(n.points_m[m - 1]);
    const ang = Math.atan2(by - ay, bx - ax);
    ctx.beginPath(); ctx.moveTo(bx, by);
    ctx.lineTo(bx - 16 * Math.cos(ang - 0.45), by - 16 * Math.sin(ang - 0.45));
    ctx.lineTo(bx - 16 * Math.cos(ang + 0.45), by - 16 * Math.sin(ang + 0.45)); ctx.fill();
    ctx.font = "600 14px system-ui";
    ctx.fillText("next probe", sx + 10, sy - 10);
    ctx.restore();
  }

  window.fbExtra = {
    onMessage(msg) {
      if (msg.type === "link") renderLink(msg);
      else if (msg.type === "posterior") {
        if (msg.groups) fillChoices(msg.groups, msg.levels);
        renderPosterior(msg);
      }
    },
    draw(ctx, P, view) { drawNext(ctx, P, view); },
    badge(f) {
      const r = $("rendering");
      r.textContent = "Remote patient (drawn from its geometry)"; r.className = "badge";
      return true;
    },
  };
  const a = STATION_CONFIG.assess || {};
  fillChoices(a.groups || [], a.levels || []);
})();
