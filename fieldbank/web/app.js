"use strict";
// The workspace page: log in, find a patient, the patient's page, the audit log. Every
// number comes from the JSON API (/api/…, described at /api/openapi.json); every text from the
// database is put in as text, never as markup. Other parts of the workspace add views and
// sections through window.fbApp (the plan composer: composer.js).
(() => {
  const meta = document.querySelector('meta[name="csrf-token"]');
  const fbApp = window.fbApp = {
    views: {}, patientSections: [], user: null, csrf: meta ? meta.content : "",
  };

  // --- building blocks -------------------------------------------------------------------
  function el(tag, attrs = {}, ...kids) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (v === null || v === undefined || v === false) continue;
      if (k === "class") e.className = v;
      else if (k === "text") e.textContent = v;
      else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
      else e.setAttribute(k, v === true ? "" : String(v));
    }
    for (const k of kids.flat(Infinity)) {
      if (k === null || k === undefined || k === false) continue;
      e.append(k instanceof Node ? k : document.createTextNode(String(k)));
    }
    return e;
  }
  const fmt = (v, d = 2) => (v === null || v === undefined || Number.isNaN(v)) ? "—"
    : Number(v).toFixed(d);
  const enc = encodeURIComponent;

  async function api(method, path, body, raw) {
    const opts = { method, headers: {}, credentials: "same-origin" };
    if (method !== "GET") opts.headers["X-CSRF-Token"] = fbApp.csrf;
    if (raw !== undefined) opts.body = raw;
    else if (body !== undefined) {
      opts.headers["Content-Type"] = "application/json";
      opts.body = JSON.stringify(body);
    }
    const r = await fetch(path, opts);
    let doc = null;
    try { doc = await r.json(); } catch (e) { doc = null; }
    if (!r.ok) {
      const err = new Error(doc && doc.error ? doc.error : `${r.status} ${r.statusText}`);
      err.status = r.status;
      if (r.status === 401 && path !== "/api/login") { fbApp.user = null; showLogin(); }
      throw err;
    }
    return doc;
  }

  function toast(text, bad = false) {
    const t = document.getElementById("toast");
    t.textContent = text;
    t.className = "toast" + (bad ? " bad" : "");
    t.hidden = !text;
    clearTimeout(toast.timer);
    if (text) toast.timer = setTimeout(() => { t.hidden = true; }, bad ? 9000 : 4000);
  }

  function page(title, ...kids) {
    const main = document.getElementById("main");
    main.replaceChildren(el("h1", {}, title), ...kids);
    document.title = `${title} · fieldbank`;
    main.focus({ preventScroll: true });
    return main;
  }

  function table(head, rows, caption) {
    return el("table", {},
      caption ? el("caption", {}, caption) : null,
      el("thead", {}, el("tr", {}, head.map((h) => el("th", { scope: "col" }, h)))),
      el("tbody", {}, rows.map((r) => el("tr", {}, r.map((c) => el("td", {}, c))))));
  }

  function section(title, ...kids) {
    const id = "s-" + title.toLowerCase().replace(/[^a-z0-9]+/g, "-");
    return el("section", { "aria-labelledby": id }, el("h2", { id }, title), ...kids);
  }

  const may = (p) => !!fbApp.user && fbApp.user.permissions.includes(p);
  Object.assign(fbApp, { el, fmt, api, toast, page, table, section, may, enc });

  // --- who is logged in -----------------------------------------------------------------
  function renderWho() {
    const who = document.getElementById("who");
    const nav = document.getElementById("nav");
    if (!fbApp.user) { who.replaceChildren(); nav.replaceChildren(); return; }
    const u = fbApp.user;
    nav.replaceChildren(...[
      el("a", { href: "#/" }, "Patients"),
      el("a", { href: "/robot" }, "Robot"),
      may("manage") ? el("a", { href: "#/audit" }, "Audit log") : null,
      el("a", { href: "/api/openapi.json" }, "API")].filter(Boolean));
    who.replaceChildren(el("span", {}, `${u.name} · ${u.role}`),
      el("button", { type: "button", class: "quiet", onclick: logout }, "Log out"));
  }

  async function logout() {
    const r = await api("POST", "/api/logout");
    fbApp.user = null; fbApp.csrf = r.csrf;
    renderWho(); showLogin();
  }

  function showLogin() {
    renderWho();
    const err = el("p", { class: "error", role: "alert" });
    const name = el("input", { id: "login-name", name: "name", autocomplete: "username",
      required: true });
    const pass = el("input", { id: "login-password", name: "password", type: "password",
      autocomplete: "current-password", required: true });
    const form = el("form", { class: "login", onsubmit: async (ev) => {
      ev.preventDefault();
      err.textContent = "";
      try {
        const r = await api("POST", "/api/login", { name: name.value, password: pass.value });
        fbApp.user = r.user; fbApp.csrf = r.csrf;
        renderWho(); route();
      } catch (e) { err.textContent = e.message; pass.value = ""; }
    } },
    el("label", { for: "login-name" }, "Account"), name,
    el("label", { for: "login-password" }, "Password"), pass,
    el("button", { type: "submit" }, "Log in"), err);
    page("Log in to the workspace", form,
      el("p", { class: "small" }, "Accounts are made with 'fieldbank users add'. "
        + "Predictions shown here are model predictions, not treatment advice."));
    name.focus();
  }

  // --- patients ---------------------------------------------------------------------------
  async function patientsView() {
    const q = el("input", { id: "find", type: "search", placeholder: "e.g. SYN-001",
      autocomplete: "off" });
    const list = el("ul", { class: "patients", "aria-live": "polite" });
    const main = page("Patients",
      el("div", { class: "find" }, el("label", { for: "find" }, "Find a patient by code"), q),
      list);
    async function load() {
      const r = await api("GET", "/api/patients?q=" + enc(q.value));
      list.replaceChildren(...r.patients.map((p) => el("li", {},
        el("a", { href: `#/patients/${enc(p.code)}` }, p.code),
        el("span", { class: "small" }, ` ${p.side} arm · ${p.sessions} session(s)`))));
      if (!r.patients.length) list.append(el("li", {}, "No patient matches."));
    }
    q.addEventListener("input", () => { clearTimeout(load.t); load.t = setTimeout(load, 150); });
    if (may("manage")) main.append(addPatientForm(load));
    await load();
    q.focus();
  }

  function addPatientForm(done) {
    const f = (id, label, attrs) => [el("label", { for: id }, label),
      el("input", { id, name: id, ...attrs })];
    const side = el("select", { id: "np-side", name: "side" },
      el("option", { value: "right" }, "right"), el("option", { value: "left" }, "left"));
    const msg = el("p", { role: "status" });
    const form = el("form", { class: "grid-form", onsubmit: async (ev) => {
      ev.preventDefault();
      const v = (id) => form.querySelector("#" + id).value;
      try {
        const r = await api("POST", "/api/patients", { code: v("np-code"),
          body_mass_kg: Number(v("np-mass")), height_m: Number(v("np-height")),
          side: side.value, notes: v("np-notes") });
        msg.textContent = `Patient ${r.code} added.`;
        form.reset(); done();
      } catch (e) { msg.textContent = e.message; }
    } },
    f("np-code", "Code (a pseudonym)", { required: true }),
    f("np-mass", "Body mass, kg", { type: "number", step: "0.1", required: true }),
    f("np-height", "Height, m", { type: "number", step: "0.01", required: true }),
    el("label", { for: "np-side" }, "Measured side"), side,
    f("np-notes", "Notes (no identifying details)", {}),
    el("button", { type: "submit" }, "Add patient"), msg);
    return section("Add a patient", form);
  }

  // --- a patient's page -------------------------------------------------------------------
  function fitBlock(f) {
    const rest = f.unidentified.length
      ? el("details", {}, el("summary", {}, `Rests on ${f.unidentified.length} parameter(s) `
          + "the maps did not identify (held at the unimpaired value)"),
        el("ul", {}, f.unidentified.map((u) => el("li", {}, el("b", {}, u.name), ": ",
          u.reason))))
      : el("p", {}, "Every fitted parameter is identified by the maps.");
    return el("article", { class: "fit" },
      el("h3", {}, `Fit ${f.id} → model ${f.model_id}` + (f.session ? ` (session ${f.session})` : "")),
      el("p", {}, `Status ${f.status}; goodness of fit ${f.verdict} (χ²/dof `
        + `${fmt(f.chi2_per_dof)}, R² ${fmt(f.r2, 3)}); ${f.algorithm}, seed ${f.seed}, `
        + `${f.evaluations} evaluations, ${fmt(f.time_s, 1)} s.`),
      f.reasons.length ? el("p", {}, "Why: " + f.reasons.join("; ")) : null,
      table(["map", "kind", "R²", "χ²/n", "verdict"], f.maps.map((m) =>
        [m.map_id, m.kind, fmt(m.r2, 3), fmt(m.chi2_per_value), m.verdict])), rest);
  }

  function mapFigures(maps) {
    const box = el("div", { class: "figures" });
    for (const m of maps) {
      box.append(el("figure", {},
        el("img", { src: `/api/maps/${m.id}/figure.svg`, loading: "lazy", width: 315,
          height: 320, alt: `${m.kind} map ${m.id} of session ${m.session}: measured `
            + (m.kind === "postural" ? "forces on the handle" : "stiffness ellipses") }),
        el("figcaption", {}, `Map ${m.id}: ${m.kind}, session ${m.session}`
          + (m.date ? ` (${m.date})` : ""))));
    }
    return box;
  }

  async function patientView(code) {
    const main = page(`Patient ${code}`, el("p", {}, "Loading…"));
    let d;
    try { d = await api("GET", `/api/patients/${enc(code)}`); }
    catch (e) { page(`Patient ${code}`, el("p", { class: "error", role: "alert" }, e.message)); return; }
    const p = d.patient;
    const latest = d.sessions.length ? d.sessions[d.sessions.length - 1].label : null;
    const extra = el("div", { id: "patient-extra" });  // the other parts' sections: plans
    main.replaceChildren(el("h1", {}, `Patient ${p.code}`),
      el("p", { class: "lead" }, `${p.side} arm measured · ${fmt(p.body_mass_kg, 1)} kg · `
        + `${fmt(p.height_m)} m` + (p.notes ? ` · ${p.notes}` : "")),
      el("p", {}, el("a", { class: "button", href: `#/patients/${enc(p.code)}/compose` },
        "Compose a plan")),
      section("Sessions", d.sessions.length ? table(["session", "date", "maps"],
        d.sessions.map((s) => [s.label, s.date || "—", s.maps])) : el("p", {}, "No session yet.")),
      section("Fits", d.fits.length ? d.fits.map(fitBlock)
        : el("p", {}, "Not fitted yet ('fieldbank fit')")),
      extra,
      section("Models", table(["model", "origin", "label", "made from"], d.models.map((m) =>
        [m.id, m.origin, m.label, m.parent_id === null ? "—" : `model ${m.parent_id}`]))),
      section("Maps", d.maps.length ? table(["map", "session", "kind", "hand speed, m/s",
        "points", "unit", "source"], d.maps.map((m) => [m.id, m.session, m.kind,
        m.velocity_m_per_s.map((v) => fmt(v)).join(", "), m.points, m.unit, m.source]))
        : el("p", {}, "No maps yet."),
      d.maps.length ? el("details", { open: true },
        el("summary", {}, `Figures of session ${latest}`),
        mapFigures(d.maps.filter((m) => m.session === latest))) : null));
    for (const add of fbApp.patientSections) add(extra, d);
    if (may("manage")) main.append(ingestForm(p.code, () => patientView(code)));
  }

  function ingestForm(code, done) {
    const msg = el("p", { role: "status" });
    const form = el("form", { class: "grid-form", onsubmit: async (ev) => {
      ev.preventDefault();
      const label = form.querySelector("#ing-session").value;
      const data = new FormData();
      for (const f of form.querySelector("#ing-files").files) data.append("file", f, f.name);
      const day = form.querySelector("#ing-date").value;
      if (day) data.append("date", day);
      try {
        const r = await api("POST", `/api/patients/${enc(code)}/sessions/${enc(label)}/files`,
          undefined, data);
        msg.textContent = `${r.stored} file(s) stored.`;
        done();
      } catch (e) { msg.textContent = e.message; }
    } },
    el("label", { for: "ing-session" }, "Session label"),
    el("input", { id: "ing-session", required: true }),
    el("label", { for: "ing-date" }, "Session date"), el("input", { id: "ing-date", type: "date" }),
    el("label", { for: "ing-files" }, "Map files (CSV, HDF5, MAT, NWB, C3D)"),
    el("input", { id: "ing-files", type: "file", multiple: true, required: true }),
    el("button", { type: "submit" }, "Ingest"), msg);
    return section("Ingest map files", form);
  }

  // --- the audit log ----------------------------------------------------------------------
  async function auditView() {
    const out = el("div");
    const f = (id, label, type = "text") => [el("label", { for: id }, label),
      el("input", { id, type })];
    const form = el("form", { class: "grid-form", onsubmit: (ev) => { ev.preventDefault(); load(); } },
      f("au-patient", "Patient"), f("au-user", "Account"), f("au-since", "Since", "date"),
      el("button", { type: "submit" }, "Show"));
    page("Audit log", form, out);
    async function load() {
      const q = new URLSearchParams();
      for (const [k, id] of [["patient", "au-patient"], ["user", "au-user"], ["since", "au-since"]]) {
        const v = form.querySelector("#" + id).value;
        if (v) q.set(k, v);
      }
      try {
        const r = await api("GET", "/api/audit?" + q.toString());
        out.replaceChildren(table(["when (UTC)", "who", "what", "on", "from", "detail"],
          r.entries.map((e) => {
            const d = Object.assign({}, e.detail); const req = d.request || {}; delete d.request;
            return [e.at.replace("T", " ").slice(0, 19), e.actor, e.action,
              `${e.entity} ${e.entity_id}`, req.from ? `${req.via} from ${req.from}` : "—",
              JSON.stringify(d)];
          }), `${r.entries.length} entries, newest first`));
      } catch (e) { out.replaceChildren(el("p", { class: "error", role: "alert" }, e.message)); }
    }
    load();
  }

  // --- routing ----------------------------------------------------------------------------
  function route() {
    if (!fbApp.user) { showLogin(); return; }
    const parts = (location.hash.replace(/^#/, "") || "/").split("/").filter(Boolean)
      .map(decodeURIComponent);
    if (parts[0] === "patients" && parts[1] && parts[2] === "compose" && fbApp.views.compose) {
      fbApp.views.compose(parts[1]);
    } else if (parts[0] === "patients" && parts[1]) {
      patientView(parts[1]);
    } else if (parts[0] === "audit") {
      auditView();
    } else {
      patientsView();
    }
  }
  fbApp.route = route;
  window.addEventListener("hashchange", route);

  document.addEventListener("DOMContentLoaded", async () => {
    try {
      const s = await api("GET", "/api/session");
      fbApp.user = s.user;
      if (s.csrf) fbApp.csrf = s.csrf;
    } catch (e) { fbApp.user = null; }
    renderWho();
    route();
  });
})();
