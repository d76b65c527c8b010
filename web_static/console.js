// SteelPath operator console: plain JS over the REST API and the event stream.
"use strict";

const API = "/api/v1";
const $ = (sel) => document.querySelector(sel);
const state = { kinds: {}, plans: new Map(), selected: null, revising: null, me: null, events: null, clouds: [] };

// Writes carry the double-submit CSRF token: the steelpath_csrf cookie's value,
// echoed in X-CSRF-Token (the server refuses a cookie-authenticated write
// without it, or from another origin).
const WRITES = new Set(["POST", "PUT", "PATCH", "DELETE"]);

function csrfCookie() {
  const c = document.cookie.split("; ").find((s) => s.startsWith("steelpath_csrf="));
  return c ? decodeURIComponent(c.slice("steelpath_csrf=".length)) : "";
}

async function csrfToken() {
  let token = csrfCookie();
  if (!token) {
    // Cleared or never set: any read gets the server to set it again.
    await fetch(API + "/health", { credentials: "same-origin" }).catch(() => {});
    token = csrfCookie();
  }
  return token;
}

// fetch() for the console: same-origin credentials and, on a write, the CSRF
// header.  referrerPolicy "same-origin" keeps the Origin header on our own
// writes, which the page's Referrer-Policy (no-referrer) would blank to "null".
async function apiFetch(url, opts = {}) {
  const method = (opts.method || "GET").toUpperCase();
  const o = { credentials: "same-origin", ...opts, headers: { ...(opts.headers || {}) } };
  if (WRITES.has(method)) {
    o.headers["X-CSRF-Token"] = await csrfToken();
    o.referrerPolicy = "same-origin";
  }
  return fetch(url, o);
}

async function api(method, path, body, isForm) {
  const opts = { method, headers: {} };
  if (body !== undefined) {
    if (isForm) opts.body = body;
    else { opts.headers["Content-Type"] = "application/json"; opts.body = JSON.stringify(body); }
  }
  const r = await apiFetch(API + path, opts);
  if (r.status === 401) { showLogin(); throw new Error("not signed in"); }
  const text = await r.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch { data = text; }
  if (!r.ok) {
    let d = data && data.detail !== undefined ? data.detail : data;
    if (d && typeof d === "object" && d.message) d = d.message;
    if (Array.isArray(d)) d = d.map((e) => `${(e.loc || []).join(".")}: ${e.msg}`).join("\n");
    // The server's words, without an "HTTP 422:" prefix a crew has no use for.
    const err = new Error(typeof d === "string" && d ? d : `${r.status} ${r.statusText || "error"}: ${JSON.stringify(d)}`);
    err.status = r.status;
    err.detail = data && data.detail !== undefined ? data.detail : null;
    throw err;
  }
  return data;
}

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") e.className = v; else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    // CSSOM, not a style attribute: the Content-Security-Policy allows no inline styles.
    else if (k === "style") e.style.cssText = v;
    else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return e;
}

function fmt(v) {
  if (typeof v === "number") return Math.abs(v) >= 1e4 || (Math.abs(v) < 1e-3 && v !== 0) ? v.toExponential(3) : (+v.toFixed(4)).toString();
  if (v === null || v === undefined) return "–";
  return String(v);
}

// ---------------------------------------------------------------- sign in
function showLogin() { $("#login").hidden = false; $("#login-token").focus(); }

$("#login-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  $("#login-error").textContent = "";
  try {
    const r = await apiFetch(API + "/session", {
      method: "POST",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ token: $("#login-token").value.trim() }),
    });
    if (!r.ok) throw new Error((await r.json()).detail || r.statusText);
    $("#login").hidden = true;
    $("#login-token").value = "";
    await start();
  } catch (e) { $("#login-error").textContent = e.message; }
});

$("#logout").addEventListener("click", async () => {
  await apiFetch(API + "/session", { method: "DELETE" });
  location.reload();
});

// ------------------------------------------------------------------ E-stop
$("#estop").addEventListener("click", async () => {
  try {
    const r = await api("POST", "/estop", { reason: "console E-stop button" });
    flash(`E-STOP sent to ${r.robot}` + (r.errors.length ? ` (errors: ${r.errors.join("; ")})` : ""));
    await loadRobots();  // the banner names the latched robots at once
  } catch (e) { flash("E-STOP FAILED: " + e.message, true); }
});

// The red banner stays while any robot's E-stop is latched: which robots,
// and the last E-stop's time, author and reason from the audit log.
let bannerKey = null;
async function renderEstopBanner() {
  const latched = (state.robots || []).filter((r) => r.estop_latched).map((r) => r.name);
  const banner = $("#estop-banner");
  banner.hidden = latched.length === 0;
  const key = latched.join(",");
  if (!latched.length || key === bannerKey) return;
  bannerKey = key;
  let since = "";
  try {
    const last = (await api("GET", "/audit?entity=robot&limit=50")).find((a) => a.action === "estop");
    if (last) since = ` since ${last.ts.replace("T", " ").slice(0, 19)} UTC by ${last.actor} (${last.reason})`;
  } catch (e) { /* the names alone still say it */ }
  $("#estop-text").textContent = `E-STOP latched on ${latched.join(", ")}${since}. ` +
    "Robots will not move until it is cleared.";
}

$("#estop-clear-all").addEventListener("click", async () => {
  const latched = state.robots.filter((r) => r.estop_latched).map((r) => r.name);
  if (!latched.length) return;
  if (!window.confirm(`Clear the E-stop on ${latched.join(", ")}? Only when every one is safe to move.`)) return;
  for (const name of latched) await clearEstop(name);
});

function flash(msg, bad) {
  const m = $("#action-msg");
  m.textContent = msg; m.className = bad ? "error" : "muted small";
  $("#scene-msg").textContent = msg;
}

// ------------------------------------------------------------------- kinds
async function loadKinds() {
  const kinds = await api("GET", "/kinds");
  const sel = $("#kind");
  sel.innerHTML = "";
  for (const k of kinds) {
    state.kinds[k.name] = k;
    sel.append(el("option", { value: k.name }, `${k.name} — ${k.title}`));
  }
  sel.addEventListener("change", () => {
    // Another kind's params mean nothing here: start from its defaults.
    state.revising = null; $("#params").value = ""; state.extraKeys = {};
    showKind();
  });
  showKind();
}

function showKind() {
  const k = state.kinds[$("#kind").value];
  // The description's first paragraph, whole (its first line alone stopped
  // mid-sentence where the docstring wraps); the full title on hover.
  const para = k ? k.description.split(/\n\s*\n/)[0].split("\n").map((l) => l.trim()).join(" ") : "";
  $("#kind-desc").textContent = para.replaceAll("``", "");
  $("#kind").title = k ? `${k.name} — ${k.title}` : "";
  $("#submit-plan").textContent = state.revising ? `Revise ${state.revising}` : "Plan";
  buildForm(k);
}

// ------------------------------------------------------- params form
// The form is built from the kind's params JSON schema (GET /kinds); the
// JSON textarea (the "advanced" tab) holds what differs from the defaults
// and is what gets submitted, so the two can never disagree: every form
// edit rewrites the JSON, every valid JSON edit refills the form.
// Units from a name's suffix (longest first): the form's labels and the
// execution view's command lines.
const UNITS = [
  ["_m_s", "m/s"], ["_rad_s", "rad/s"], ["_deg_s2", "°/s²"], ["_mm_deg", "mm, °"], ["_mm", "mm"],
  ["_m", "m"], ["_s", "s"], ["_rad", "rad"], ["_deg", "°"], ["_kg", "kg"], ["_pct", "%"], ["_hz", "Hz"],
];
const COMMON_FIELDS = 8;  // scalar fields shown before "More parameters"

function labelOf(name, prop) {
  const u = UNITS.find(([suffix]) => name.endsWith(suffix) && name.length > suffix.length);
  let title = prop.title || name;
  if (u) {  // "Voxel M" → "Voxel" (m): the suffix's words leave the title
    const words = title.split(" ");
    const n = u[0].split("_").length - 1;
    if (words.length > n) title = words.slice(0, -n).join(" ");
  }
  return { title, unit: u ? u[1] : "" };
}

// The schema of one field with $ref / allOf resolved and Optional (anyOf
// with null) unwrapped: { base, nullable }.
function resolveField(prop, defs) {
  const deref = (p) => {
    if (p && p.$ref) return defs[p.$ref.split("/").pop()] || {};
    if (p && p.allOf && p.allOf.length === 1) return deref(p.allOf[0]);
    return p || {};
  };
  let p = deref(prop);
  let nullable = false;
  if (p.anyOf) {
    const rest = p.anyOf.filter((o) => o.type !== "null");
    nullable = rest.length < p.anyOf.length;
    p = rest.length === 1 ? deref(rest[0]) : { anyOf: rest };
  }
  return { base: { ...prop, ...p, anyOf: p.anyOf }, nullable };
}

function fieldKind(base, name) {
  if (base.enum) return "enum";
  // A stored cloud is picked from the list, not typed as an id.
  if (name === "cloud_id" && base.type === "string") return "cloud";
  if (base.type === "boolean") return "bool";
  if (base.type === "integer" || base.type === "number") return "number";
  if (base.type === "string") return "string";
  return "json";  // arrays, tuples, nested models, unions: edited as JSON
}

function buildForm(k) {
  const box = $("#params-form");
  box.innerHTML = "";
  state.form = null;
  if (!k) return;
  const schema = k.params_schema || {};
  const defs = schema.$defs || {};
  const fields = [];
  for (const [name, prop] of Object.entries(schema.properties || {})) {
    const { base, nullable } = resolveField(prop, defs);
    fields.push({ name, prop, base, nullable, kind: fieldKind(base, name), dflt: k.defaults[name] });
  }
  const common = fields.filter((f) => f.kind !== "json").slice(0, COMMON_FIELDS);
  const more = fields.filter((f) => !common.includes(f));
  for (const f of common) box.append(fieldRow(f));
  if (more.length) {
    const det = el("details", {}, el("summary", {}, `More parameters (${more.length})`));
    for (const f of more) det.append(fieldRow(f));
    box.append(det);
  }
  state.form = { kind: k.name, fields };
  formFromJson();
}

function fieldRow(f) {
  const { title, unit } = labelOf(f.name, f.prop);
  const id = `pf-${f.name}`;
  let input;
  if (f.kind === "enum") {
    input = el("select", { id });
    if (f.nullable) input.append(el("option", { value: "" }, "— none —"));
    for (const v of f.base.enum) input.append(el("option", { value: JSON.stringify(v) }, String(v)));
  } else if (f.kind === "cloud") {
    input = el("select", { id, class: "cloud-picker" });
    fillCloudPicker(input, f.nullable);
  } else if (f.kind === "bool") {
    input = el("input", { id, type: "checkbox" });
  } else if (f.kind === "number") {
    input = el("input", { id, type: "number", step: f.base.type === "integer" ? "1" : "any" });
    const lo = f.base.minimum ?? f.base.exclusiveMinimum;
    const hi = f.base.maximum ?? f.base.exclusiveMaximum;
    if (lo !== undefined) input.setAttribute("min", lo);
    if (hi !== undefined) input.setAttribute("max", hi);
    if (f.nullable) input.setAttribute("placeholder", "automatic");
  } else if (f.kind === "string") {
    input = el("input", { id, type: "text" });
    if (f.nullable) input.setAttribute("placeholder", "none");
  } else {
    input = el("textarea", { id, rows: "2", spellcheck: "false", class: "json-field" });
  }
  input.dataset.field = f.name;
  const onChange = ["enum", "bool", "cloud"].includes(f.kind);
  input.addEventListener(onChange ? "change" : "input", () => jsonFromForm());
  const row = el("label", { class: "field", for: id, "data-field": f.name },
    el("span", { class: "name" }, title, unit ? el("span", { class: "unit" }, ` (${unit})`) : ""),
    input,
    el("span", { class: "hint" }, (f.prop.description || "") + rangeText(f.base)),
    el("span", { class: "field-error" }));
  if (f.kind === "bool") { row.insertBefore(input, row.firstChild); row.classList.add("bool"); }
  if (f.kind === "json" && f.nullable) input.setAttribute("placeholder", "none");
  return row;
}

function rangeText(b) {
  const parts = [];
  if (b.minimum !== undefined) parts.push(`≥ ${b.minimum}`);
  if (b.exclusiveMinimum !== undefined) parts.push(`> ${b.exclusiveMinimum}`);
  if (b.maximum !== undefined) parts.push(`≤ ${b.maximum}`);
  if (b.exclusiveMaximum !== undefined) parts.push(`< ${b.exclusiveMaximum}`);
  return parts.length ? ` [${parts.join(", ")}]` : "";
}

function setFieldError(name, msg) {
  const row = document.querySelector(`#params-form .field[data-field="${name}"]`);
  if (!row) return false;
  row.classList.toggle("invalid", !!msg);
  row.querySelector(".field-error").textContent = msg || "";
  if (msg) { const d = row.closest("details"); if (d) d.open = true; }
  return true;
}

function clearFieldErrors() {
  for (const r of document.querySelectorAll("#params-form .field.invalid")) {
    r.classList.remove("invalid"); r.querySelector(".field-error").textContent = "";
  }
  $("#form-unknown").textContent = "";
}

// One field's value from its input: { value } or { error }.
function readField(f) {
  const input = document.getElementById(`pf-${f.name}`);
  if (f.kind === "bool") return { value: input.checked };
  const raw = input.value;
  if (f.kind === "enum") return raw === "" ? { value: null } : { value: JSON.parse(raw) };
  if (f.kind === "cloud") return raw === "" ? (f.nullable ? { value: null } : { error: "pick a cloud" }) : { value: raw };
  // A number box holds "" for text that is no number ("ten"): say so, not "required".
  if (f.kind === "number" && input.validity && input.validity.badInput) {
    return { error: "not a number: type digits, e.g. 2.5" };
  }
  if (raw.trim() === "") {
    if (f.nullable) return { value: null };
    if (f.kind === "string") return { value: "" };
    return { error: "a value is required" };
  }
  if (f.kind === "number") {
    const v = Number(raw);
    if (!Number.isFinite(v)) return { error: `not a number: ${raw}` };
    if (f.base.type === "integer" && !Number.isInteger(v)) return { error: "must be a whole number" };
    const b = f.base;
    if (b.minimum !== undefined && v < b.minimum) return { error: `must be ≥ ${b.minimum}` };
    if (b.exclusiveMinimum !== undefined && v <= b.exclusiveMinimum) return { error: `must be > ${b.exclusiveMinimum}` };
    if (b.maximum !== undefined && v > b.maximum) return { error: `must be ≤ ${b.maximum}` };
    if (b.exclusiveMaximum !== undefined && v >= b.exclusiveMaximum) return { error: `must be < ${b.exclusiveMaximum}` };
    return { value: v };
  }
  if (f.kind === "string") return { value: raw };
  try { return { value: JSON.parse(raw) }; } catch (e) { return { error: `not valid JSON: ${e.message}` }; }
}

function writeField(f, v) {
  const input = document.getElementById(`pf-${f.name}`);
  if (!input) return;
  if (f.kind === "bool") input.checked = !!v;
  else if (f.kind === "enum") input.value = v === null || v === undefined ? "" : JSON.stringify(v);
  else if (f.kind === "cloud") {
    const id = v === null || v === undefined ? "" : String(v);
    // An id not (or no longer) listed stays selectable, so revising keeps it.
    if (id && ![...input.options].some((o) => o.value === id)) input.append(el("option", { value: id }, `${id} (not in the list)`));
    input.value = id;
  } else if (f.kind === "json") input.value = v === undefined || (v === null && f.nullable) ? "" : JSON.stringify(v);
  else input.value = v === null || v === undefined ? "" : String(v);
  input.closest(".field").classList.toggle("changed", JSON.stringify(v) !== JSON.stringify(f.dflt));
}

// Form → JSON: the fields that differ from the defaults.
function jsonFromForm() {
  if (!state.form) return;
  clearFieldErrors();
  const out = {};
  let bad = false;
  for (const f of state.form.fields) {
    const r = readField(f);
    if (r.error) { setFieldError(f.name, r.error); bad = true; continue; }
    const changed = JSON.stringify(r.value) !== JSON.stringify(f.dflt);
    document.querySelector(`#params-form .field[data-field="${f.name}"]`).classList.toggle("changed", changed);
    if (changed) out[f.name] = r.value;
  }
  for (const [key, v] of Object.entries(state.extraKeys || {})) out[key] = v;  // shown as unknown
  if (!bad) $("#params").value = Object.keys(out).length ? JSON.stringify(out, null, 2) : "";
  return !bad;
}

// JSON → form: defaults overlaid with the JSON's values; unknown keys named.
function formFromJson() {
  if (!state.form) return;
  const text = $("#params").value.trim();
  let obj = {};
  if (text) {
    try { obj = JSON.parse(text); } catch (e) { $("#form-unknown").textContent = `JSON: ${e.message}`; return; }
    if (obj === null || typeof obj !== "object" || Array.isArray(obj)) {
      $("#form-unknown").textContent = "params must be a JSON object"; return;
    }
  }
  clearFieldErrors();
  const known = new Set(state.form.fields.map((f) => f.name));
  state.extraKeys = {};
  for (const [key, v] of Object.entries(obj)) if (!known.has(key)) state.extraKeys[key] = v;
  const unknown = Object.keys(state.extraKeys);
  if (unknown.length) {
    $("#form-unknown").textContent =
      `unknown field${unknown.length > 1 ? "s" : ""} ${unknown.map((u) => `'${u}'`).join(", ")}: ` +
      `${state.form.kind} has no such parameter (see the form for the ones it has)`;
  }
  for (const f of state.form.fields) writeField(f, f.name in obj ? obj[f.name] : f.dflt);
}

function showTab(which) {
  const json = which === "json";
  if (!json && !$("#params-json").hidden) formFromJson();
  if (json && !$("#params-form").hidden) jsonFromForm();
  $("#params-json").hidden = !json;
  $("#params-form").hidden = json;
  $("#tab-json").classList.toggle("active", json);
  $("#tab-form").classList.toggle("active", !json);
  $("#tab-json").setAttribute("aria-selected", String(json));
  $("#tab-form").setAttribute("aria-selected", String(!json));
}
$("#tab-form").addEventListener("click", () => showTab("form"));
$("#tab-json").addEventListener("click", () => showTab("json"));
$("#params").addEventListener("input", () => { $("#submit-error").textContent = ""; formFromJson(); });
// An error shown for what was submitted goes once the operator changes the form.
$("#params-form").addEventListener("input", () => { $("#submit-error").textContent = ""; });

// A 422 from the server names the field: shown at the field when the form
// has it, at the top otherwise.
function showServerErrors(err) {
  const detail = err.detail;
  if (!Array.isArray(detail)) return false;
  const known = new Set((state.form ? state.form.fields : []).map((f) => f.name));
  if (detail.some((e) => known.has(String((e.loc || [])[0]))) && $("#params-form").hidden) {
    showTab("form");  // the errors are shown at their fields
  }
  let shown = false;
  for (const e of detail) {
    const name = (e.loc || [])[0];
    if (e.type === "extra_forbidden") {
      $("#form-unknown").textContent += `unknown field '${(e.loc || []).join(".")}' `; shown = true;
    } else if (name !== undefined && setFieldError(String(name), `${(e.loc || []).slice(1).join(".")} ${e.msg}`.trim())) {
      shown = true;
    }
  }
  return shown;
}

$("#defaults").addEventListener("click", () => {
  $("#submit-error").textContent = "";  // an old refusal is not about the defaults
  $("#params").value = "";
  state.extraKeys = {};
  formFromJson();
});

$("#submit-plan").addEventListener("click", async () => {
  $("#submit-error").textContent = "";
  if (!$("#params-form").hidden && !jsonFromForm()) {
    $("#submit-error").textContent = "fix the marked fields first"; return;
  }
  let params = {};
  const text = $("#params").value.trim();
  if (text) {
    try { params = JSON.parse(text); } catch (e) { $("#submit-error").textContent = "params: " + e.message; return; }
  }
  try {
    const plan = state.revising
      ? await api("POST", `/plans/${state.revising}/revise`, { params })
      : await api("POST", "/plans", { kind: $("#kind").value, params });
    state.revising = null; showKind();
    upsertPlan(plan);
    await select(plan.id);
    showInScene(plan.id);
  } catch (e) {
    showServerErrors(e);
    $("#submit-error").textContent = e.message;
  }
});

// ------------------------------------------------------------------ clouds
async function loadSamples() {
  const samples = await api("GET", "/clouds/samples");
  const sel = $("#sample");
  sel.innerHTML = "";
  for (const [name, kind] of Object.entries(samples)) sel.append(el("option", { value: name }, `${name} (${kind})`));
}

// The form's cloud field: the stored clouds (newest first), or none — the
// kind's own built-in scene.
function fillCloudPicker(sel, nullable) {
  const keep = sel.value;
  sel.innerHTML = "";
  sel.append(el("option", { value: "" }, nullable ? "— none: the kind's built-in scene —" : "— pick a cloud —"));
  for (const c of state.clouds) sel.append(el("option", { value: c.id }, `${c.name} · ${c.n_points.toLocaleString("en-US")} pts · ${c.id}`));
  if (keep && ![...sel.options].some((o) => o.value === keep)) sel.append(el("option", { value: keep }, `${keep} (not in the list)`));
  sel.value = keep;
}

async function loadClouds() {
  const clouds = await api("GET", "/clouds?limit=20");
  state.clouds = clouds;
  for (const f of (state.form ? state.form.fields : []).filter((x) => x.kind === "cloud")) {
    const sel = document.getElementById(`pf-${f.name}`);
    if (sel) fillCloudPicker(sel, f.nullable);
  }
  const ul = $("#clouds");
  ul.innerHTML = "";
  for (const c of clouds) {
    const li = el("li", { title: "show in scene", onclick: () => showCloud(c.id) },
      `${c.id} · ${c.name} · ${c.n_points} pts` + (c.dropped_nonfinite ? ` (${c.dropped_nonfinite} dropped)` : ""));
    // Colour by: the cloud's stored RGB / intensity, or height (a plain click: RGB when it has it).
    const colours = ["rgb", "intensity"].filter((a) => (c.attributes || []).includes(a));
    for (const by of colours.length ? [...colours, "height"] : []) {
      li.append(" · ", el("a", { href: "#", title: `show coloured by ${by}`, "data-colour-by": by,
        onclick: (ev) => { ev.preventDefault(); ev.stopPropagation(); showCloud(c.id, by); } }, by));
    }
    ul.append(li);
  }
}

// A refused cloud reads as an error, not as the small grey note of a success.
function cloudMsg(text) { const m = $("#cloud-msg"); m.textContent = text; m.className = "muted small"; }
function cloudError(text) { const m = $("#cloud-msg"); m.textContent = text; m.className = "error"; }

$("#load-sample").addEventListener("click", async () => {
  try {
    const c = await api("POST", "/clouds", { sample: $("#sample").value });
    cloudMsg(`stored ${c.id}: ${c.n_points} points`);
    await loadClouds();
    showCloud(c.id);
  } catch (e) { cloudError(e.message); }
});

$("#upload-cloud").addEventListener("click", async () => {
  const f = $("#cloud-file").files[0];
  if (!f) { cloudError("choose a file first"); return; }
  const fd = new FormData();
  fd.append("file", f);
  try {
    const c = await api("POST", "/clouds", fd, true);
    cloudMsg(`stored ${c.id}: ${c.n_points} points, ${c.dropped_nonfinite} non-finite rows dropped`);
    await loadClouds();
  } catch (e) { cloudError(e.message); }
});

async function showCloud(id, colourBy = "auto") {
  try { await api("POST", "/scene/show", { cloud_id: id, colour_by: colourBy }); } catch (e) { flash(e.message, true); }
}

// ------------------------------------------------------------------- plans
async function loadPlans() {
  const plans = await api("GET", "/plans?limit=100");
  state.plans.clear();
  for (const p of plans.reverse()) state.plans.set(p.id, p);
  renderPlans();
}

function upsertPlan(p) {
  const old = state.plans.get(p.id) || {};
  state.plans.set(p.id, { ...old, ...p });
  renderPlans();
}

function renderPlans() {
  const tb = $("#plans tbody");
  tb.innerHTML = "";
  const rows = [...state.plans.values()].sort((a, b) => (b.created_at || "").localeCompare(a.created_at || ""));
  for (const p of rows) {
    const tr = el("tr", { "data-id": p.id, "data-state": p.state, onclick: () => select(p.id) },
      el("td", { title: p.id }, p.id), el("td", { title: p.kind || "" }, p.kind || ""),
      el("td", { title: p.state }, el("span", { class: `state ${p.state}` }, p.state)),
      el("td", {}, `${Math.round((p.progress || 0) * 100)}%`));
    if (p.id === state.selected) tr.classList.add("sel");
    tb.append(tr);
  }
  if (!rows.length) {
    tb.append(el("tr", {}, el("td", { colspan: "4", class: "empty" },
      "no plans yet: choose a kind above and press Plan")));
  }
}

async function select(id) {
  // A message about the plan shown before ("dispatched as ex_…") must not
  // read as if it were about this one.
  if (state.selected !== id) { $("#action-msg").textContent = ""; $("#action-msg").className = "muted small"; }
  state.selected = id;
  renderPlans();
  const p = await api("GET", `/plans/${id}`);
  upsertPlan(p);
  // A plan event re-selects the selected plan (its state changed); if the
  // operator picked another plan while that fetch was out, the older answer
  // must not redraw the detail over the newer choice.
  if (state.selected !== id) return;
  renderDetail(p);
  renderComparison(p);
  // findings.js and replay.js follow the selected plan
  document.dispatchEvent(new CustomEvent("steelpath:selected", { detail: p }));
}

// A revision beside its parent: the params that changed, every check whose
// verdict or value changed (a FAIL → PASS is better, PASS → FAIL worse) and
// every metric both report, with the difference.  Metrics carry no "better"
// direction in their schema, so only checks are judged.
async function renderComparison(p) {
  const box = $("#d-compare");
  box.hidden = true;
  if (!p.parent_id) return;
  let parent;
  try { parent = await api("GET", `/plans/${p.parent_id}`); } catch (e) { return; }
  if (state.selected !== p.id) return;  // another plan was selected meanwhile
  $("#d-compare-parent").textContent = parent.id;
  const tb = box.querySelector("tbody");
  tb.innerHTML = "";
  const row = (cls, name, a, b, change, verdict) => {
    const tr = el("tr", { class: cls, "data-compare": name },
      el("td", {}, name), el("td", {}, a), el("td", {}, b), el("td", {}, change));
    if (verdict) tr.dataset.verdict = verdict;
    tb.append(tr);
  };
  const json = (v) => (v === undefined ? "–" : JSON.stringify(v));
  const keys = new Set([...Object.keys(parent.params || {}), ...Object.keys(p.params || {})]);
  for (const k of [...keys].sort()) {
    const a = (parent.params || {})[k], b = (p.params || {})[k];
    if (JSON.stringify(a) !== JSON.stringify(b)) row("param", `params.${k}`, json(a), json(b), "changed");
  }
  const pc = Object.fromEntries((parent.checks || []).map((c) => [c.name, c]));
  for (const c of p.checks || []) {
    const o = pc[c.name];
    if (!o) { row("check", c.name, "–", c.passed ? "PASS" : "FAIL", "new check"); continue; }
    if (o.passed !== c.passed) {
      const better = c.passed;
      row(`check ${better ? "better" : "worse"}`, c.name, o.passed ? "PASS" : "FAIL",
        c.passed ? "PASS" : "FAIL", better ? "better: now passes" : "worse: now fails", better ? "better" : "worse");
    } else if (typeof c.value === "number" && typeof o.value === "number" && c.value !== o.value) {
      row("check", c.name, fmt(o.value), fmt(c.value), `${c.value > o.value ? "+" : ""}${fmt(c.value - o.value)}`);
    }
  }
  const pm = parent.metrics || {};
  for (const [k, v] of Object.entries(p.metrics || {}).sort()) {
    if (typeof v !== "number" || typeof pm[k] !== "number" || v === pm[k]) continue;
    row("metric", k, fmt(pm[k]), fmt(v), `${v > pm[k] ? "+" : ""}${fmt(v - pm[k])}`);
  }
  if (!tb.children.length) row("same", "no difference", "", "", "");
  box.hidden = false;
}

function renderDetail(p) {
  $("#detail").hidden = false;
  // The program's planned timeline: seconds done after k commands (k = 0…n).
  state.timeline = null;
  if (p.program) {
    const t = [0];
    for (const c of p.program) t.push(t[t.length - 1] + Math.max(Number(c.duration_s) || 0, 0));
    state.timeline = { plan: p.id, t };
  }
  $("#d-title").textContent = `${p.id} · ${p.kind}` + (p.parent_id ? ` (revision of ${p.parent_id})` : "")
    + (p.finding_id ? ` (from finding ${p.finding_id})` : "");
  const st = $("#d-state");
  st.textContent = p.state; st.className = `state ${p.state}`;
  $("#d-progress div").style.width = `${(p.progress || 0) * 100}%`;
  $("#d-progress span").textContent = `${Math.round((p.progress || 0) * 100)}% ${p.stage || ""}`;
  $("#d-error").textContent = p.error || "";
  const allowed = new Set(p.allowed_actions || []);
  $("#approve").disabled = !allowed.has("approve");
  $("#cancel").disabled = !allowed.has("cancel");
  $("#revise").disabled = !allowed.has("revise");
  $("#delete").disabled = !allowed.has("delete");
  $("#dispatch").disabled = !allowed.has("dispatch") || !p.program;
  // Say why Dispatch is greyed, on hover, not only inside the program section.
  const noProgram = (p.result && p.result.program_note) || "this kind has no robot program";
  $("#dispatch").title = p.program ? "" : noProgram;
  applyRole();
  $("#dispatch-box").hidden = true;
  $("#d-program-len").textContent = p.program ? `(${p.program.length} commands)` : `(${noProgram})`;
  $("#d-program").textContent = p.program ? p.program.map((c, i) => `${i}: ${JSON.stringify(c)}`).join("\n") : "";
  renderOutputs($("#d-outputs"), p.result ? planOutputs(p.id) : []);
  loadExecutionFor(p.id);
  const ct = $("#d-checks tbody");
  ct.innerHTML = "";
  for (const c of p.checks || []) {
    ct.append(el("tr", { "data-check": c.name },
      el("td", { class: c.passed ? "pass" : "fail" }, c.passed ? "PASS" : "FAIL"),
      el("td", {}, c.name), el("td", {}, c.message || `${fmt(c.value)} / ${fmt(c.limit)}`)));
  }
  renderMetrics(p.metrics || {});
  $("#d-params").textContent = JSON.stringify(p.params, null, 2);
  const at = $("#d-audit tbody");
  at.innerHTML = "";
  for (const a of p.audit || []) {
    at.append(el("tr", {}, el("td", {}, a.ts.replace("T", " ").slice(0, 19)), el("td", {}, a.actor),
      el("td", {}, a.action), el("td", {}, `${a.from_state || ""} → ${a.to_state || ""}`), el("td", {}, a.reason || "")));
  }
  renderPlots((p.result && p.result.plots) || []);
}

// Metrics as a reader takes them: a title and a unit from the name's suffix
// (UNITS), counts as whole numbers, grouped (safety, geometry, time, counts),
// the first few shown and the rest folded; the raw name on hover for API users.
const METRICS_SHOWN = 8;
// Names whose words alone would read twice as "Planning time".
const METRIC_TITLES = { job_time_s: "Planning time", planning_time_s: "Planner's own time" };
const SAFETY_WORDS = /clearance|margin|collision|infeasible|unreach|fail|risk|violat|refus|uncovered|not_/;

function metricGroup(name, unit, v) {
  if (SAFETY_WORDS.test(name)) return 0;
  if (["m", "mm", "rad", "°", "mm, °"].includes(unit)) return 1;
  if (unit === "s") return 2;
  if (Number.isInteger(v)) return 3;
  return 4;
}

function metricValue(v) {
  if (typeof v !== "number" || !Number.isFinite(v)) return fmt(v);
  if (Number.isInteger(v)) return v.toLocaleString("en-US");
  const a = Math.abs(v);
  if (a >= 1000) return v.toLocaleString("en-US", { maximumFractionDigits: 1 });
  if (a >= 1) return (+v.toFixed(3)).toString();
  return v === 0 ? "0" : Number(v.toPrecision(3)).toString();
}

function renderMetrics(metrics) {
  const mt = $("#d-metrics tbody");
  mt.innerHTML = "";
  const rows = Object.entries(metrics).map(([name, v]) => {
    const u = UNITS.find(([suffix]) => name.endsWith(suffix) && name.length > suffix.length);
    const unit = u ? u[1] : "";
    const words = (u ? name.slice(0, -u[0].length) : name).replaceAll("_", " ");
    return { name, v, unit, title: words.charAt(0).toUpperCase() + words.slice(1), group: metricGroup(name, unit, v) };
  });
  // The planning time every kind has (measured around the kind's run) leads.
  rows.sort((a, b) => (a.name === "job_time_s" ? -1 : b.name === "job_time_s" ? 1 : a.group - b.group || a.title.localeCompare(b.title)));
  const row = (r) => el("tr", { title: r.name, "data-metric": r.name },
    el("td", {}, METRIC_TITLES[r.name] || r.title),
    el("td", {}, metricValue(r.v) + (r.unit ? ` ${r.unit}` : "")));
  rows.slice(0, METRICS_SHOWN).forEach((r) => mt.append(row(r)));
  if (rows.length > METRICS_SHOWN) {
    const more = el("tr", { class: "metrics-more" }, el("td", { colspan: "2" },
      el("a", { href: "#", onclick: (ev) => {
        ev.preventDefault();
        more.replaceWith(...rows.slice(METRICS_SHOWN).map(row));
      } }, `${rows.length - METRICS_SHOWN} more…`)));
    mt.append(more);
  }
}

// Plots: uPlot (vendored in web_static/vendor/uplot, MIT) with axes, ticks,
// units, legend, hover read-out and drag-to-zoom (double-click resets).  Long
// series are decimated for display by keeping each bucket's min and max, so
// peaks survive; the stored arrays keep every sample.
const PLOT_MAX_POINTS = 4000;
const PLOT_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"];

function decimate(xs, series) {
  const n = xs.length;
  if (n <= PLOT_MAX_POINTS) return [xs, series];
  const buckets = Math.floor(PLOT_MAX_POINTS / 2), keep = new Set([0, n - 1]);
  for (let b = 0; b < buckets; b++) {
    const lo = Math.floor((b * n) / buckets), hi = Math.floor(((b + 1) * n) / buckets);
    for (const ys of series) {
      let imin = -1, imax = -1;
      for (let j = lo; j < hi; j++) {
        if (!Number.isFinite(ys[j])) continue;
        if (imin < 0 || ys[j] < ys[imin]) imin = j;
        if (imax < 0 || ys[j] > ys[imax]) imax = j;
      }
      if (imin >= 0) { keep.add(imin); keep.add(imax); }
    }
  }
  const idx = [...keep].sort((a, b) => a - b);
  return [idx.map((j) => xs[j]), series.map((ys) => idx.map((j) => ys[j]))];
}

function renderPlots(plots) {
  const box = $("#d-plots");
  for (const u of state.uplots || []) u.destroy();
  state.uplots = [];
  box.innerHTML = "";
  for (const pl of plots) {
    const names = Object.keys(pl.series || {});
    if (!(pl.x || []).length || !names.length) continue;
    const clean = (ys) => ys.map((v) => (Number.isFinite(v) ? v : null));
    const [xs, ys] = decimate(pl.x, names.map((n) => pl.series[n]));
    const div = el("div", { class: "plot", "data-points": String(pl.x.length), "data-shown": String(xs.length) });
    box.append(div);
    const opts = {
      title: pl.title || "",
      width: Math.max(320, box.clientWidth - 10),
      height: 220,
      scales: { x: { time: false } },
      series: [{ label: pl.x_label || "x" },
        ...names.map((n, i) => ({ label: n, stroke: PLOT_COLORS[i % PLOT_COLORS.length], width: 1.5, spanGaps: false }))],
      axes: [{ label: pl.x_label || "" }, { label: pl.y_label || "" }],
    };
    state.uplots.push(new uPlot(opts, [xs, ...ys.map(clean)], div));
  }
}

// Charts follow the page's width (a window resized, a console on a wider screen).
let plotResize = null;
window.addEventListener("resize", () => {
  clearTimeout(plotResize);
  plotResize = setTimeout(() => {
    const w = Math.max(320, $("#d-plots").clientWidth - 10);
    for (const u of state.uplots || []) if (Math.abs(u.width - w) > 2) u.setSize({ width: w, height: u.height });
  }, 150);
});

async function act(path, body) {
  try {
    const r = await api("POST", path, body);
    flash(`${path.split("/").pop()}: ${r.state || r.outcome || "ok"}`);
    await select(state.selected);
  } catch (e) { flash(e.message, true); }
}

$("#approve").addEventListener("click", () => act(`/plans/${state.selected}/approve`, { comment: "approved in console" }));
$("#cancel").addEventListener("click", () => act(`/plans/${state.selected}/cancel`));
$("#show").addEventListener("click", () => showInScene(state.selected));
$("#revise").addEventListener("click", () => {
  const p = state.plans.get(state.selected);
  if (!p) return;
  state.revising = p.id;
  $("#kind").value = p.kind;
  showKind();  // rebuilds the form for the plan's kind …
  $("#params").value = Object.keys(p.params || {}).length ? JSON.stringify(p.params, null, 2) : "";
  formFromJson();  // … and fills it with the plan's params
  showTab("form");
});
$("#delete").addEventListener("click", async () => {
  if (!confirm(`Delete plan ${state.selected}?`)) return;
  try {
    await api("DELETE", `/plans/${state.selected}`);
    state.plans.delete(state.selected);
    state.selected = null;
    $("#detail").hidden = true;
    renderPlans();
  } catch (e) { flash(e.message, true); }
});

async function showInScene(id) {
  if (!id) return;
  try {
    const r = await api("POST", "/scene/show", { plan_id: id });
    $("#scene-msg").textContent = r.shown ? `showing ${r.shown}` : r.reason || "";
  } catch (e) { $("#scene-msg").textContent = e.message; }
}

// -------------------------------------------------------------- measuring
// Shift-clicks in the scene pick points; the server pairs them and sends a
// `measurement` event per pick (GET /scene holds the last one).
const fmtPoint = (p) => `(${p.map((v) => v.toFixed(3)).join(", ")}) m`;
function showMeasurement(m) {
  const text = $("#measure-text");
  $("#measure-clear").hidden = !m || m.state === "missed";
  if (!m) { text.textContent = "shift-click two points in the scene"; text.className = "muted"; return; }
  if (m.state === "missed") { text.textContent = "no drawn point under the cursor: shift-click on the cloud or the plan"; text.className = "muted"; return; }
  if (m.state === "first") { text.textContent = `first point ${fmtPoint(m.point_m)}: shift-click the second`; text.className = ""; return; }
  text.textContent = `${Math.round(m.distance_mm).toLocaleString("en-US")} mm  from ${fmtPoint(m.a_m)} to ${fmtPoint(m.b_m)}`;
  text.className = "measure-value";
}
async function loadMeasurement() {
  try {
    const s = await api("GET", "/scene");
    showMeasurement(s.measurement ? { state: "measured", ...s.measurement } : null);
  } catch (e) { /* the scene is optional */ }
}
$("#measure-clear").onclick = async () => {
  try { await api("DELETE", "/scene/measurement"); showMeasurement(null); } catch (e) { flash(e.message, true); }
};

// -------------------------------------------------------- scene proposals
// Scene clicks (start/end vertex, surface…) only propose; an operator decides here.
async function loadProposals() {
  let items = [];
  try { items = await api("GET", "/scene/proposals?state=pending"); } catch (e) { return; }
  const tb = $("#proposals tbody");
  tb.innerHTML = "";
  const canDecide = state.me && state.me.role !== "viewer";
  for (const p of items) {
    // A finding proposal (Ctrl/Cmd-click on a face) asks what was found first (findings.js).
    const finding = p.action === "finding" && typeof window.openFindingForm === "function";
    const accept = el("button", { class: "accept", onclick: () => (finding ? window.openFindingForm(p) : decideProposal(p.id, "accept")) }, finding ? "Accept…" : "Accept");
    const dismiss = el("button", { class: "secondary dismiss", onclick: () => decideProposal(p.id, "dismiss") }, "Dismiss");
    accept.disabled = dismiss.disabled = !canDecide;
    tb.append(el("tr", { "data-proposal": p.id },
      el("td", {}, p.created_at.replace("T", " ").slice(11, 19)),
      el("td", {}, finding ? `finding on ${p.plan_id}` : `${p.kind} from ${p.plan_id}`),
      el("td", { title: JSON.stringify(p.patch) }, describePatch(p.patch)),
      el("td", { class: "muted" }, p.source),
      el("td", { class: "actions" }, accept, " ", dismiss)));
  }
  $("#proposals-empty").hidden = items.length > 0;
}

// What a proposal changes, as words: "member m3 · face f2 · point (x, y, z) m".
function describePatch(patch) {
  const num = (v) => (Number.isInteger(v) ? String(v) : v.toFixed(3));
  return Object.entries(patch || {}).map(([k, v]) => {
    const u = UNITS.find(([suffix]) => k.endsWith(suffix) && k.length > suffix.length);
    const name = (u ? k.slice(0, -u[0].length) : k).replace(/_id$/, "").replaceAll("_", " ");
    const unit = u ? ` ${u[1]}` : "";
    if (Array.isArray(v) && v.every((x) => typeof x === "number")) return `${name} (${v.map(num).join(", ")})${unit}`;
    if (Array.isArray(v)) return `${name}: ${v.length} item${v.length === 1 ? "" : "s"}`;
    if (typeof v === "number") return `${name} ${num(v)}${unit}`;
    if (v && typeof v === "object") return `${name}: ${Object.keys(v).length} fields`;
    return `${name} ${v}`;
  }).join(" · ");
}

async function decideProposal(id, action) {
  try {
    const r = await api("POST", `/scene/proposals/${id}/${action}`);
    if (action === "accept") {
      flash(`proposal ${id} accepted: planning ${r.id}`);
      upsertPlan(r);
      await select(r.id);
      showInScene(r.id);  // the new plan is the selected one in both
    } else flash(`proposal ${id} dismissed`);
  } catch (e) { flash(e.message, true); }
  loadProposals();
}

// ---------------------------------------------------------- robots & runs
state.robots = [];
state.execution = null;

async function loadRobots() {
  renderRobots(await api("GET", "/robots"));
}

// Heartbeat ages from the last statuses, ticking locally: the statuses
// themselves come with the event stream (no polling of GET /robots).
function heartbeatAge(r) {
  return r.last_heartbeat ? `${Math.max(0, Date.now() / 1000 - r.last_heartbeat).toFixed(1)} s ago` : "never";
}
setInterval(() => {
  for (const r of state.robots || []) {
    const cell = document.querySelector(`#robots tr[data-robot="${r.name}"] td.hb`);
    if (cell) cell.textContent = heartbeatAge(r);
  }
}, 1000);

function renderRobots(robots) {
  state.robots = robots;
  const tb = $("#robots tbody");
  tb.innerHTML = "";
  for (const r of state.robots) {
    const hb = heartbeatAge(r);
    const faults = (r.faults ? `0x${r.faults.toString(16)}` : "none") + (r.estop_latched ? " · E-STOP latched" : "");
    const clear = el("button", { class: "secondary operator-only", onclick: () => clearEstop(r.name) }, "clear E-stop");
    clear.disabled = !r.estop_latched;
    tb.append(el("tr", { "data-robot": r.name, "data-link": r.state },
      el("td", {}, r.name), el("td", { class: `link-${r.state}` }, r.state),
      el("td", { title: r.reason }, r.url + (r.emulated ? " (emulator)" : "")),
      el("td", { class: "hb" }, hb), el("td", {}, faults), el("td", {}, clear)));
  }
  renderEstopBanner();
  applyRole();
  const sel = $("#dispatch-robot");
  const keep = sel.value;
  sel.innerHTML = "";
  for (const r of state.robots) sel.append(el("option", { value: r.name }, `${r.name} (${r.state})`));
  if (keep) sel.value = keep;
}

async function clearEstop(name) {
  try { await api("POST", `/robots/${name}/clear-estop`); flash(`E-stop cleared on ${name}`); await loadRobots(); }
  catch (e) { flash(e.message, true); }
}

$("#dispatch").addEventListener("click", () => {
  const p = state.plans.get(state.selected);
  const kind = p && state.kinds[p.kind];
  if (kind && kind.robot) $("#dispatch-robot").value = kind.robot;
  $("#dispatch-box").hidden = false;
});
$("#dispatch-cancel").addEventListener("click", () => { $("#dispatch-box").hidden = true; });
$("#dispatch-confirm").addEventListener("click", async () => {
  try {
    const ex = await api("POST", `/plans/${state.selected}/dispatch`, { robot: $("#dispatch-robot").value });
    $("#dispatch-box").hidden = true;
    flash(`dispatched as ${ex.id}`);
    showExecution(ex);
    await select(state.selected);
  } catch (e) { flash(e.message, true); }
});

async function loadExecutionFor(planId) {
  const runs = await api("GET", `/executions?plan_id=${planId}`);
  if (runs.length) showExecution(runs[0]); else { state.execution = null; $("#execution").hidden = true; }
}

async function showExecution(ex) {
  const full = await api("GET", `/executions/${ex.id}`);
  state.execution = full;
  $("#execution").hidden = false;
  $("#x-id").textContent = full.id;
  const st = $("#x-state");
  st.textContent = full.state; st.className = `state ${full.state}`;
  // Progress by planned time (the bar) and by command (the count).
  const tl = state.timeline && state.timeline.plan === full.plan_id ? state.timeline.t : null;
  const tDone = tl ? tl[Math.min(full.acked, tl.length - 1)] : null;
  const tAll = tl ? tl[tl.length - 1] : null;
  const frac = tl && tAll > 0 ? tDone / tAll : full.progress;
  $("#x-progress div").style.width = `${frac * 100}%`;
  $("#x-progress span").textContent = `${full.acked}/${full.total} commands`
    + (tl ? ` · ${tDone.toFixed(1)} of ${tAll.toFixed(1)} s planned` : "");
  $("#x-current").textContent = full.current_command ? describeCommand(full.current_command) : "–";
  $("#x-fault").textContent = NEXT_ACTION[full.state]
    ? `${full.state}${stoppedAt(full)}: ${full.fault || full.error || "no reason given"} — ${NEXT_ACTION[full.state]}` : "";
  const allowed = new Set(full.allowed_actions || []);
  $("#x-pause").disabled = !allowed.has("pause");
  $("#x-resume").disabled = !allowed.has("resume");
  $("#x-abort").disabled = !allowed.has("abort");
  renderOutputs($("#x-outputs"), executionOutputs(full.id));
  applyRole();
}

// What a plan and a run produce, as links the browser fetches with the session's cookie.
function planOutputs(id) {
  const q = encodeURIComponent(id);
  return [
    ["Report", `${API}/reports/${q}`, "open the inspection report (HTML) in a new tab", false],
    ["Report PDF", `${API}/reports/${q}?format=pdf`, "the report as a PDF", true],
    ["Plan export", `${API}/plans/${q}/export`, "the plan's history as a zip another server imports", true],
    ["Audit trail", `${API}/audit?entity=plan&entity_id=${q}`, "who did what to this plan, as JSON", false],
  ];
}

function executionOutputs(id) {
  const q = encodeURIComponent(id);
  return [
    ["MCAP", `${API}/executions/${q}/recording.mcap`, "the run for Foxglove (MCAP)", true],
    ["ROS 2 bag", `${API}/executions/${q}/recording.mcap?format=rosbag2`, "the run as a zipped ROS 2 bag", true],
    ["Audit trail", `${API}/audit?entity=execution&entity_id=${q}`, "who did what to this run, as JSON", false],
  ];
}

function renderOutputs(box, links) {
  box.replaceChildren();
  box.hidden = !links.length;
  if (!links.length) return;
  box.append("Outputs: ");
  links.forEach(([label, href, title, download], i) => {
    if (i) box.append(" · ");
    const a = el("a", { href, title, target: "_blank", rel: "noopener" }, label);
    if (download) a.setAttribute("download", "");
    box.append(a);
  });
}

// " at <time> (<actor>)" of the transition that left the execution in its state.
function stoppedAt(ex) {
  const last = (ex.audit || []).find((e) => e.to_state === ex.state);
  if (!last) return "";
  const when = new Date(last.ts).toLocaleTimeString();
  return ` at ${when}` + (last.actor ? ` (${last.actor})` : "");
}

// What the operator does next, shown with the reason while an execution waits.
const NEXT_ACTION = {
  interrupted: "once the robot is safe (its E-stop cleared, if one was pressed), Resume: it continues from the last acknowledged command; or Abort to end the run",
  faulted: "fix the fault's cause, then Resume (it clears the robot's fault) or Abort",
};

// A robot command as a line: its op, then each field with the unit its name
// carries (speeds_m_s → m/s, duration_s → s, …).
// (UNITS: the suffix table the params form uses too.)
function describeCommand(c) {
  const num = (v) => (typeof v === "number" ? Number(v.toPrecision(4)).toString() : String(v));
  const parts = [];
  for (const [k, v] of Object.entries(c)) {
    if (k === "op") continue;
    const u = UNITS.find(([suffix]) => k.endsWith(suffix));
    const name = u ? k.slice(0, -u[0].length) : k;
    const val = Array.isArray(v) ? v.map(num).join(", ") : (v && typeof v === "object" ? JSON.stringify(v) : num(v));
    parts.push(`${name.replaceAll("_", " ")} ${val}${u ? " " + u[1] : ""}`);
  }
  return `${c.op || "command"}: ${parts.join("; ")}`;
}

for (const action of ["pause", "resume", "abort"]) {
  $(`#x-${action}`).addEventListener("click", async () => {
    if (!state.execution) return;
    if (action === "abort" && !window.confirm(
      `Abort execution ${state.execution.id}? The run ends for good: the robot stops where it is and the rest of its program is not run. `
      + "An aborted plan cannot be resumed or dispatched again; Revise it to plan anew.")) return;
    try {
      const ex = await api("POST", `/executions/${state.execution.id}/${action}`, action === "resume" ? {} : undefined);
      showExecution(ex);
    } catch (e) { flash(e.message, true); }
  });
}

// ------------------------------------------------------------------- audit
let auditLimit = 20;
async function loadAudit() {
  const events = await api("GET", `/audit?limit=${auditLimit}`);
  $("#audit-count").textContent = `latest ${events.length}`;
  $("#audit-more").hidden = events.length < auditLimit;
  const tb = $("#audit tbody");
  tb.innerHTML = "";
  for (const a of events) {
    tb.append(el("tr", {}, el("td", {}, a.ts.replace("T", " ").slice(0, 19)), el("td", {}, a.actor),
      el("td", {}, `${a.entity} ${a.entity_id}`), el("td", {}, a.action),
      el("td", {}, a.to_state ? `${a.from_state || ""} → ${a.to_state}` : ""), el("td", {}, a.reason || "")));
  }
}

$("#audit-more").addEventListener("click", () => { auditLimit = Math.min(2000, auditLimit + 50); loadAudit(); });

// ------------------------------------------------------------------ events
function openEvents() {
  if (state.events) state.events.close();
  // Robots' statuses ride on the stream every 3 s (event: robots).
  const es = new EventSource(API + "/events?robots_every_s=3");
  es.addEventListener("robots", (m) => renderRobots(JSON.parse(m.data)));
  state.events = es;
  es.onopen = () => {
    $("#conn").classList.add("live");
    // What changed before this (re)connection was not streamed to us: the
    // list read at start-up can predate a plan's last event.
    loadPlans().catch(() => {});
  };
  es.onerror = () => $("#conn").classList.remove("live");
  let auditTimer = null;
  const refreshAudit = () => { clearTimeout(auditTimer); auditTimer = setTimeout(loadAudit, 300); };
  es.addEventListener("plan", (m) => {
    const d = JSON.parse(m.data);
    if (d.state === "deleted") { state.plans.delete(d.id); renderPlans(); return; }
    const before = (state.plans.get(d.id) || {}).state;
    upsertPlan(d);
    if (d.id === state.selected) {
      $("#d-progress div").style.width = `${(d.progress || 0) * 100}%`;
      $("#d-progress span").textContent = `${Math.round((d.progress || 0) * 100)}% ${d.stage || ""}`;
      if (before !== d.state) select(d.id);
    }
    if (!["planning"].includes(d.state)) refreshAudit();
  });
  es.addEventListener("proposal", () => loadProposals());
  es.addEventListener("measurement", (m) => showMeasurement(JSON.parse(m.data)));
  // The server ends the stream when this session's token is revoked or expires.
  es.addEventListener("auth", (m) => {
    es.close();
    $("#conn").classList.remove("live");
    $("#login-error").textContent = JSON.parse(m.data).detail || "signed out";
    showLogin();
  });
  let robotTimer = null;
  const refreshRobots = () => { if (!robotTimer) robotTimer = setTimeout(() => { robotTimer = null; loadRobots(); }, 500); };
  for (const t of ["estop", "cloud", "execution", "robot", "finding"]) {
    es.addEventListener(t, (m) => {
      const d = JSON.parse(m.data);
      if (t === "estop") { flash(`E-STOP (${d.robot}) by ${d.by}`, true); refreshRobots(); }
      if (t === "cloud") loadClouds();
      if (t === "execution" && state.execution && d.id === state.execution.id) showExecution(d);
      if (t === "robot") {
        // A link-state change carries the new state: no need to ask again.
        // A state report (frequent) changes nothing the table shows.
        if (d.report !== undefined) return;
        const r = (state.robots || []).find((x) => x.name === d.name);
        const linkOnly = Object.keys(d).every((k) => ["id", "ts", "name", "url", "state", "reason"].includes(k));
        if (r && d.state && linkOnly) {
          r.state = d.state; if (d.reason !== undefined) r.reason = d.reason;
          renderRobots(state.robots);
        } else refreshRobots();  // E-stop clears, take-overs: rare, read them whole
        return;
      }
      refreshAudit();
      document.dispatchEvent(new CustomEvent("steelpath:" + t, { detail: d }));
    });
  }
}

// -------------------------------------------------------------------- role
// What a viewer's token may not do stays on screen but disabled, with the
// reason on hover; the E-stop button (operator) is absent for a viewer.
const OPERATOR_CONTROLS = ["#submit-plan", "#load-sample", "#upload-cloud", "#approve", "#dispatch",
  "#cancel", "#revise", "#delete", "#x-pause", "#x-resume", "#x-abort", "#show", "#measure-clear"];

function applyRole() {
  if (!state.me || state.me.role !== "viewer") return;
  const why = `needs the operator role; ${state.me.name} is a viewer (read-only)`;
  for (const b of [...OPERATOR_CONTROLS.map((q) => $(q)), ...document.querySelectorAll(".operator-only")]) {
    if (!b) continue;
    b.disabled = true;
    b.title = why;
  }
  $("#estop").hidden = true;
  $("#readonly").hidden = false;
}

// The data volume as /health reports it: nothing when fine, a warning when low,
// and when full that writes are refused and which safety records wait.
function showDisk(disk) {
  const box = $("#disk");
  if (!disk || disk.state === "ok") { box.hidden = true; return; }
  const free = disk.free_mb == null ? "" : ` (${disk.free_mb} MiB free)`;
  const waiting = disk.audit_pending ? `; ${disk.audit_pending} audit record(s) waiting to be written` : "";
  box.textContent = disk.state === "full"
    ? `Disk full${free}: new plans and uploads are refused${waiting}`
    : `Disk space low${free}${waiting}`;
  box.classList.toggle("disk-full", disk.state === "full");
  box.hidden = false;
}

// ------------------------------------------------------------------- start
async function start() {
  const me = await api("GET", "/session");
  state.me = me;
  $("#whoami").textContent = `${me.name} (${me.role})`;
  $("#logout").hidden = false;
  applyRole();
  const health = await fetch(API + "/health").then((r) => r.json());
  showDisk(health.disk);
  setInterval(() => {
    fetch(API + "/health").then((r) => r.json()).then((h) => showDisk(h.disk)).catch(() => {});
  }, 15000);
  await Promise.all([loadKinds(), loadSamples(), loadClouds(), loadPlans(), loadAudit(), loadRobots(), loadProposals(), loadMeasurement()]);
  openEvents();
  if (health.scene.running) {
    $("#scene").src = "/scene/";
    if (me.role === "viewer") {  // the server passes a viewer's camera only
      $("#scene-msg").textContent = "read-only scene: picks, measuring and proposals need the operator role";
      $("#measure").hidden = true;
    }
  } else {
    // No empty black box: say why there is no scene, where it would be.
    $("#scene-msg").textContent = "scene not running";
    $("#scene").hidden = true;
    $("#measure").hidden = true;
  }
}

start().catch((e) => { if (e.message !== "not signed in") console.error(e); });
