"use strict";
// The plan composer: the catalogue's interventions with their units, the what-if updating as a
// dose changes (POST /api/whatif: the numbers of 'fieldbank whatif'), the optimiser, Feel it
// (the pair pushed to the robot, then the robot view), save and mark given. Also the plans
// section of a patient's page. Built on window.fbApp (app.js).
(() => {
  const app = window.fbApp;
  const { el, fmt, api, toast, page, table, section, may, enc } = app;
  const GROUPS = [["sf", "shoulder flexors"], ["se", "shoulder extensors"],
    ["ef", "elbow flexors"], ["ee", "elbow extensors"], ["bf", "bi-articular flexors"],
    ["be", "bi-articular extensors"]];
  const DEBOUNCE_MS = 120;
  const fb = window.fbComposer = { requests: 0, answered: 0, last: null, saved: null };

  const num = (id, attrs = {}) => el("input", { id, name: id, type: "number", min: 0,
    inputmode: "decimal", ...attrs });

  function doseTable() {
    return el("table", { class: "doses" },
      el("caption", {}, "Per muscle group; empty or 0: none"),
      el("thead", {}, el("tr", {}, el("th", { scope: "col" }, "group"),
        el("th", { scope: "col" }, "botulinum, U"), el("th", { scope: "col" }, "lengthening, cm"),
        el("th", { scope: "col" }, "casting, mm"), el("th", { scope: "col" }, "tenotomy"))),
      el("tbody", {}, GROUPS.map(([g, name]) => el("tr", {},
        el("th", { scope: "row" }, el("abbr", { title: name }, g), name),
        el("td", {}, num(`bt-${g}`, { step: 10, max: 1000, "aria-label": `botulinum into ${name}, U` })),
        el("td", {}, num(`len-${g}`, { step: 0.5, max: 5, "aria-label": `lengthening of ${name}, cm` })),
        el("td", {}, num(`cast-${g}`, { step: 1, max: 30, "aria-label": `casting of ${name}, mm` })),
        el("td", {}, el("input", { id: `ten-${g}`, type: "checkbox", "aria-label": `tenotomy of ${name}` }))))));
  }

  function reflexRow(kind, label, factor) {
    return el("div", { class: "row" },
      el("input", { id: `${kind}-on`, type: "checkbox" }),
      el("label", { for: `${kind}-on` }, label),
      el("label", { for: `${kind}-groups` }, "groups"),
      el("input", { id: `${kind}-groups`, value: "all", size: 8 }),
      el("label", { for: `${kind}-factor` }, "β ×"),
      num(`${kind}-factor`, { step: 0.05, max: 1, value: factor }));
  }

  // the request: the command line's text forms, built from the fields
  function fields(form) {
    const v = (id) => form.querySelector("#" + id);
    const val = (id) => Number(v(id).value || 0);
    const out = { botox: [], lengthen: [], cast: [], tenotomy: [] };
    for (const [g] of GROUPS) {
      if (val(`bt-${g}`) > 0) out.botox.push(`${g}=${val(`bt-${g}`)}U`);
      if (val(`len-${g}`) > 0) out.lengthen.push(`${g}=${val(`len-${g}`)}cm`);
      if (val(`cast-${g}`) > 0) out.cast.push(`${g}=${val(`cast-${g}`)}mm`);
      if (v(`ten-${g}`).checked) out.tenotomy.push(g);
    }
    const req = { botox: out.botox.join(","), lengthen: out.lengthen.join(","),
      cast: out.cast, tenotomy: out.tenotomy };
    if (out.botox.length && v("bt-weeks").value !== "") req.weeks = Number(v("bt-weeks").value);
    for (const k of ["rhizotomy", "baclofen"]) {
      if (v(`${k}-on`).checked) req[k] = `${v(`${k}-groups`).value || "all"}:${v(`${k}-factor`).value}`;
    }
    if (v("plan-label").value) req.label = v("plan-label").value;
    const model = v("model").value;
    if (model) req.model_id = Number(model);
    return req;
  }
  const empty = (r) => !r.botox && !r.lengthen && !r.cast.length && !r.tenotomy.length
    && !r.rhizotomy && !r.baclofen;

  function range(pair, d = 2) { return `[${fmt(pair[0], d)}, ${fmt(pair[1], d)}]`; }

  function render(out, doc) {
    const grades = doc.comparison.severity;
    const star = (x) => (x.unidentified && x.unidentified.length ? "*" : "");
    out.grades.replaceChildren(table(["group", "contracture (passive)", "spasticity (dynamic)"],
      GROUPS.map(([g, name]) => {
        const b = grades.before[g], a = grades.after[g];
        return [`${g} ${name}`, `${b.passive.level}${star(b.passive)} → ${a.passive.level}${star(a.passive)}`,
          `${b.dynamic.level}${star(b.dynamic)} → ${a.dynamic.level}${star(a.dynamic)}`];
      }), "Severity per muscle group, before → after; * rests on a parameter the fit did not identify"));
    const st = doc.comparison.stretches;
    out.stretches.replaceChildren(table(["joint stretch", "slow 5°/s, N·m", "fast 180°/s, N·m",
      "velocity-dependent, N·m"], Object.entries(st).map(([name, s]) => [name,
      `${fmt(s.before.slow_torque_n_m)} → ${fmt(s.after.slow_torque_n_m)}`,
      `${fmt(s.before.peak_torque_n_m)} → ${fmt(s.after.peak_torque_n_m)}`,
      `${fmt(s.before.reflex_torque_n_m)} → ${fmt(s.after.reflex_torque_n_m)}`]),
      "Resisting torque of each joint stretch, before → after"));
    const iv = doc.intervals;
    out.intervals.replaceChildren(iv && Object.keys(iv.metrics || {}).length
      ? table(["metric", "before", "after", "change"], Object.entries(iv.metrics).map(([k, m]) => [
        `${k}, ${m.unit}${m.rests_on_guess ? "*" : ""}`, `${fmt(m.before)} ${range(m.before_interval)}`,
        `${fmt(m.after)} ${range(m.after_interval)}`, `${fmt(m.change)} ${range(m.change_interval)}`]),
      `95% intervals: ${iv.note}`)
      : el("p", {}, iv && iv.note ? `No intervals: ${iv.note}.` : "No intervals."));
    out.warnings.replaceChildren(...(doc.warnings.length
      ? doc.warnings.map((w) => el("li", {}, w)) : [el("li", { class: "none" }, "none")]));
    const fit = doc.fit;
    out.lines.replaceChildren(...doc.summary.lines.map((l) => el("p", {}, l)),
      el("p", { class: "small" }, `Model: ${doc.model.source}`
        + (fit ? `; fit ${fit.fit_id}: status ${fit.status}, goodness of fit ${fit.goodness_of_fit}` : "")
        + ". Model predictions, not treatment advice."));
    if (fb.figureUrl) URL.revokeObjectURL(fb.figureUrl);
    fb.figureUrl = URL.createObjectURL(new Blob([doc.figure_svg], { type: "image/svg+xml" }));
    out.figure.replaceChildren(el("img", { id: "whatif-figure", src: fb.figureUrl,
      alt: `What-if figures for ${doc.plan_label}: joint stretches, the moving field, grades `
        + "and probing motions, before and after" }));
  }

  async function compose(code) {
    const models = el("select", { id: "model" }, el("option", { value: "" }, "latest fitted model"));
    const form = el("form", { id: "plan-form", onsubmit: (ev) => ev.preventDefault() },
      el("div", { class: "row" }, el("label", { for: "model" }, "Model before"), models),
      el("fieldset", {}, el("legend", {}, "Interventions"), doseTable(),
        el("div", { class: "row" }, el("label", { for: "bt-weeks" }, "Weeks after the injection"),
          num("bt-weeks", { step: 1, max: 52, value: 5 }),
          el("span", { class: "small" }, "onabotulinumtoxinA (Botox®) units"))),
      el("fieldset", {}, el("legend", {}, "Reflex reduction"),
        reflexRow("rhizotomy", "selective dorsal rhizotomy", 0.4),
        reflexRow("baclofen", "intrathecal baclofen", 0.5)),
      el("div", { class: "row" }, el("label", { for: "plan-label" }, "Plan label"),
        el("input", { id: "plan-label", maxlength: 200, size: 28 })));
    const out = { lines: el("div", { id: "summary-lines" }), warnings: el("ul", { id: "warnings", class: "warnings" }),
      grades: el("div", { id: "grades" }), intervals: el("div", { id: "intervals" }),
      stretches: el("div", { id: "stretches" }), figure: el("div", { class: "figure-box" }) };
    const status = el("p", { id: "compose-status", class: "small", role: "status" });
    const saveBtn = el("button", { id: "save", type: "button", disabled: !may("plan") }, "Save plan");
    const feelBtn = el("button", { id: "feel", type: "button", disabled: !may("robot") }, "Feel it on the robot");
    const giveDate = el("input", { id: "give-date", type: "date", value: new Date().toISOString().slice(0, 10) });
    const giveBtn = el("button", { id: "give", type: "button", disabled: true }, "Mark given");
    const saved = el("p", { id: "saved", role: "status" });
    const actions = el("div", { class: "row" }, feelBtn, saveBtn,
      el("label", { for: "give-date" }, "given on"), giveDate, giveBtn);
    const noRole = !may("plan") ? el("p", { class: "small" }, `A ${app.user.role} reads and `
      + "explores; saving, giving and the robot need a clinician.") : null;
    const opt = el("fieldset", {}, el("legend", {}, "Optimiser: the botulinum split closest to unimpaired"),
      el("div", { class: "row" }, el("label", { for: "opt-total" }, "dose limit, U"),
        num("opt-total", { value: 300, step: 10 }), el("label", { for: "opt-groups" }, "groups"),
        el("input", { id: "opt-groups", value: "ef,bf", size: 10 }),
        el("button", { id: "optimise", type: "button", disabled: !may("plan") }, "Find the split")));
    page(`Plan for patient ${code}`,
      el("p", { class: "lead" }, el("a", { href: `#/patients/${enc(code)}` }, `← patient ${code}`)),
      el("div", { class: "composer" }, el("div", { class: "c-form" }, form, opt),
        el("div", { class: "c-summary" }, el("section", { class: "summary", "aria-labelledby": "sum-h",
          id: "summary", "aria-live": "polite" }, el("h2", { id: "sum-h" }, "What the plan changes"),
        out.lines, status), actions, saved, noRole),
        el("div", { class: "c-rest" },
          section("Warnings", out.warnings), section("Grades", out.grades),
          section("Joint stretches", out.stretches), section("Intervals", out.intervals),
          section("Figures", out.figure))));
    const key = `compose:${code}`;
    const restore = JSON.parse(sessionStorage.getItem(key) || "{}");
    for (const [id, v] of Object.entries(restore)) {
      const f = form.querySelector("#" + id);
      if (f && f.type === "checkbox") f.checked = v; else if (f) f.value = v;
    }
    let seq = 0;
    async function update() {
      const state = {};
      form.querySelectorAll("input, select").forEach((f) => { state[f.id] = f.type === "checkbox" ? f.checked : f.value; });
      sessionStorage.setItem(key, JSON.stringify(state));
      const req = fields(form);
      fb.saved = null; giveBtn.disabled = true; saved.textContent = "";
      if (empty(req)) { status.textContent = "Choose an intervention: a dose, a length, a group."; return; }
      const mine = ++seq; fb.requests += 1;
      status.textContent = "computing…";
      try {
        const doc = await api("POST", "/api/whatif", { patient: code, ...req });
        if (mine !== seq) return;  // a newer dose is on its way
        fb.last = doc; fb.answered += 1;
        render(out, doc);
        status.textContent = `plan: ${doc.plan_label}`;
      } catch (e) {
        if (mine === seq) { status.textContent = e.message; fb.error = e.message; }
      }
    }
    form.addEventListener("input", () => { clearTimeout(update.t); update.t = setTimeout(update, DEBOUNCE_MS); });
    fb.update = update;
    saveBtn.addEventListener("click", async () => {
      try {
        const r = await api("POST", "/api/plans", { patient: code, ...fields(form) });
        fb.saved = r; giveBtn.disabled = false;
        saved.textContent = `Saved as plan ${r.plan_id} (model ${r.base_model_id} → model ${r.result_model_id}).`;
      } catch (e) { saved.textContent = e.message; }
    });
    giveBtn.addEventListener("click", async () => {
      if (!fb.saved) return;
      try {
        const r = await api("POST", `/api/plans/${fb.saved.plan_id}/give`, { on: giveDate.value });
        saved.textContent = `Plan ${r.id} recorded as given on ${r.given_on}.`;
        giveBtn.disabled = true;
      } catch (e) { saved.textContent = e.message; }
    });
    feelBtn.addEventListener("click", async () => {
      feelBtn.disabled = true;
      status.textContent = "starting the robot and pushing before (A) and after (B)…";
      try {
        const body = { patient: code, ...fields(form) };
        if (fb.saved) body.plan_id = fb.saved.plan_id;
        const r = await api("POST", "/api/whatif/feel", body);
        fb.felt = r;
        toast(`On the ${r.simulated ? "simulated " : ""}robot: A = before, B = after.`);
        location.assign(r.view);
      } catch (e) {
        status.replaceChildren(e.message, " ", el("a", { href: "/robot" }, "Open the robot view"));
        feelBtn.disabled = false;
      }
    });
    document.getElementById("optimise").addEventListener("click", async () => {
      status.textContent = "searching the split…";
      try {
        const groups = document.getElementById("opt-groups").value.split(",").map((s) => s.trim()).filter(Boolean);
        const doc = await api("POST", "/api/whatif/optimise", { patient: code,
          total_units: Number(document.getElementById("opt-total").value), groups,
          model_id: fields(form).model_id });
        const units = doc.plan.steps[0].units;
        for (const [g] of GROUPS) form.querySelector(`#bt-${g}`).value = units[g] ? Math.round(units[g]) : "";
        update();
      } catch (e) { status.textContent = e.message; }
    });
    try {
      const d = await api("GET", `/api/patients/${enc(code)}`);
      for (const m of d.models) models.append(el("option", { value: m.id }, `model ${m.id}: ${m.origin}, ${m.label}`));
      if (restore.model) models.value = restore.model;
    } catch (e) { status.textContent = e.message; }
    update();
  }
  app.views.compose = compose;

  // --- the plans of a patient's page -------------------------------------------------------
  app.patientSections.push(async (where, d) => {
    const box = section("Plans", el("p", {}, "Loading…"));
    where.append(box);
    let r;
    try { r = await api("GET", `/api/patients/${enc(d.patient.code)}/plans`); }
    catch (e) { box.replaceChildren(el("h2", {}, "Plans"), el("p", { class: "error" }, e.message)); return; }
    const rows = r.plans.map((p) => {
      const check = p.check ? p.check.verdict : (p.given_on ? "not checked" : "—");
      const give = !p.given_on && may("plan") ? el("button", { type: "button", class: "quiet",
        onclick: async () => {
          try { await api("POST", `/api/plans/${p.id}/give`, { on: new Date().toISOString().slice(0, 10) });
            app.route(); } catch (e) { toast(e.message, true); }
        } }, "Given today") : null;
      return [p.id, p.label, p.steps.join("; "),
        p.given_on ? el("span", { class: "given" }, p.given_on) : el("span", {}, "explored ", give),
        `${p.base_model_id} → ${p.result_model_id}`,
        p.warnings.length ? `${p.warnings.length} warning(s): ${p.warnings[0]}` : "none",
        el("span", { class: `verdict-${String(check).split(" ")[0]}` }, check)];
    });
    box.replaceChildren(el("h2", { id: "s-plans" }, "Plans"), rows.length
      ? table(["plan", "label", "steps", "given", "models", "rests on", "checked against later maps"], rows)
      : el("p", {}, "No plans yet."),
    rows.length ? el("p", {}, el("a", { id: "report-link",
      href: `/api/patients/${enc(d.patient.code)}/report.html`, download: "" },
    "Download the report of these plans"), " (HTML: each plan's figures, grades, intervals "
      + "and the check against later maps; to keep or print)") : null);
  });
})();
