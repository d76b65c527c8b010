// Findings beside the selected inspection plan, and the form
// that confirms a finding proposed from the scene (Ctrl/Cmd-click on a face).
// Uses console.js's globals: state, api, $, el, flash, select, loadProposals.
"use strict";

(() => {
  const TYPES = ["corrosion", "coating_loss", "section_loss", "crack", "deformation", "loose_fastener", "other"];
  const CONDITION = { 1: "good", 2: "fair", 3: "poor", 4: "severe" };
  const KINDS = ["ara.inspect", "ara.navigate"];
  const BLASTABLE = ["corrosion", "coating_loss"];
  const box = $("#findings-box");
  const fs = { plan: null, items: [], type: "", min: 1, withdrawn: false, framed: null };

  const canWrite = () => !!state.me && state.me.role !== "viewer";
  const whyNot = () => `needs the operator role; ${state.me ? state.me.name : "you"} are a viewer (read-only)`;
  const label = (t) => t.replace(/_/g, " ");

  // An operator control: disabled for a viewer (as applyRole() does) or for `reason`.
  function opButton(text, cls, onclick, reason) {
    const b = el("button", { class: `${cls} operator-only small`, onclick: (ev) => { ev.stopPropagation(); onclick(); } }, text);
    if (!canWrite()) { b.disabled = true; b.title = whyNot(); } else if (reason) { b.disabled = true; b.title = reason; }
    return b;
  }

  function typeOptions(selected, withAll) {
    const opts = withAll ? [el("option", { value: "" }, "all types")] : [];
    for (const t of TYPES) {
      const o = el("option", { value: t }, label(t));
      if (t === selected) o.selected = true;
      opts.push(o);
    }
    return opts;
  }

  function csOptions(selected, prefix) {
    return [1, 2, 3, 4].map((k) => {
      const o = el("option", { value: String(k) }, `${prefix}${k} ${CONDITION[k]}`);
      if (k === selected) o.selected = true;
      return o;
    });
  }

  async function load() {
    const p = fs.plan;
    if (!p) return;
    try {
      const q = `?plan_id=${encodeURIComponent(p.id)}&include_deleted=${fs.withdrawn}`;
      const items = await api("GET", `/findings${q}`);
      if (fs.plan !== p) return;  // another plan was selected meanwhile
      fs.items = items;
    } catch (e) { fs.items = []; flash(e.message, true); }
    render();
  }

  function place(f) {
    if (f.cluster_id !== null && f.cluster_id !== undefined) return `cluster ${f.cluster_id}`;
    return f.face_id !== null && f.face_id !== undefined ? `member ${f.member_id} / face ${f.face_id}` : `member ${f.member_id}`;
  }

  function maintenance(f) {
    const out = el("div", { class: "f-plans small" });
    for (const m of f.maintenance_plans || []) {
      const bits = [`${m.kind} ${m.plan_id}`, m.state || "deleted"];
      if (m.outcome) bits.push(m.outcome);
      if (m.coverage_pct !== null && m.coverage_pct !== undefined) bits.push(`${Math.round(m.coverage_pct)} % covered`);
      const a = el("a", { href: "#", class: "f-plan", "data-plan": m.plan_id }, bits.join(" · "));
      a.addEventListener("click", (ev) => { ev.preventDefault(); ev.stopPropagation(); if (m.state) select(m.plan_id); });
      out.append(a);
    }
    return out;
  }

  function review(f) {
    const wrap = el("div", { class: "f-review row small" },
      el("span", { class: "f-badge awaiting" }, "awaiting new condition state"));
    const pick = el("select", { class: "f-new-cs operator-only" }, ...csOptions(f.condition_state, ""));
    pick.addEventListener("click", (ev) => ev.stopPropagation());
    if (!canWrite()) { pick.disabled = true; pick.title = whyNot(); }
    wrap.append(pick, opButton("Set", "secondary f-set-cs", async () => {
      try {
        await api("PATCH", `/findings/${f.id}`, { condition_state: Number(pick.value) });
        flash(`finding ${f.id}: condition state ${pick.value} (${CONDITION[pick.value]})`);
        load();
      } catch (e) { flash(e.message, true); }
    }));
    return wrap;
  }

  async function makePlan(f, kind) {
    try {
      const r = await api("POST", `/findings/${f.id}/plan`, { kind });
      flash(`${kind} plan ${r.id} from finding ${f.id}`);
      if (typeof upsertPlan === "function") upsertPlan(r);
      await select(r.id);
      // The scene shows what the detail shows: the new plan, not the inspection.
      if (typeof showInScene === "function") showInScene(r.id);
    } catch (e) { flash(e.message, true); }
  }

  async function frame(f) {
    fs.framed = f.id;
    for (const tr of box.querySelectorAll("tr[data-finding]")) tr.classList.toggle("framed", tr.dataset.finding === f.id);
    if (!canWrite()) return;  // the scene is the operator's
    try {
      await api("POST", "/scene/frame", { finding_id: f.id });
      $("#scene-msg").textContent = `looking at finding ${f.id} (${label(f.type)}, ${place(f)})`;
    } catch (e) { $("#scene-msg").textContent = e.message; }
  }

  function row(f) {
    const tr = el("tr", { "data-finding": f.id, "data-cs": String(f.condition_state), class: `cs-${f.condition_state}` });
    if (f.deleted) tr.classList.add("withdrawn");
    if (f.id === fs.framed) tr.classList.add("framed");
    tr.title = "click: frame the scene on it";
    tr.addEventListener("click", () => frame(f));
    const what = el("td", {},
      el("b", {}, label(f.type)), " ", el("span", { class: "muted" }, place(f)));
    if (f.notes) what.append(el("div", { class: "f-notes small" }, f.notes));
    const n = (f.photos || []).length;
    what.append(el("div", { class: "muted small" }, `${n} photo${n === 1 ? "" : "s"}` +
      (f.deleted ? ` · withdrawn by ${f.deleted_by}: ${f.deleted_reason || ""}` : "")));
    what.append(maintenance(f));
    if (f.awaiting_review && !f.deleted) what.append(review(f));
    const acts = el("td", { class: "actions" });
    if (!f.deleted) {
      const onFace = f.face_id !== null && f.face_id !== undefined;
      acts.append(opButton("Blast plan", "secondary f-blast", () => makePlan(f, "blast"),
        !BLASTABLE.includes(f.type) ? "a blast plan is made from a corrosion or coating-loss finding"
          : !onFace ? "a blast plan needs the finding on a face" : null));
      const hasMember = f.member_id !== null && f.member_id !== undefined;
      acts.append(" ", opButton("Close inspection", "secondary f-inspect", () => makePlan(f, "ara.inspect"),
        hasMember ? null : "a close inspection drives to a member; this finding names none"));
    }
    tr.append(
      el("td", {}, el("span", { class: `f-cs cs-${f.condition_state}`, title: CONDITION[f.condition_state] },
        `${f.condition_state} ${CONDITION[f.condition_state]}`)),
      what, acts);
    return tr;
  }

  function render() {
    const p = fs.plan;
    box.innerHTML = "";
    if (!p) return;
    const shown = fs.items.filter((f) => (!fs.type || f.type === fs.type) && f.condition_state >= fs.min);
    const typeSel = el("select", { id: "f-type" }, ...typeOptions(fs.type, true));
    typeSel.addEventListener("change", () => { fs.type = typeSel.value; render(); });
    const minSel = el("select", { id: "f-min" }, ...csOptions(fs.min, "≥ "));
    minSel.addEventListener("change", () => { fs.min = Number(minSel.value); render(); });
    const gone = el("input", { type: "checkbox", id: "f-withdrawn" });
    gone.checked = fs.withdrawn;
    gone.addEventListener("change", () => { fs.withdrawn = gone.checked; load(); });
    box.append(
      el("h4", {}, "Findings ", el("span", { class: "muted small", id: "f-count" },
        shown.length === fs.items.length ? `${fs.items.length}` : `${shown.length} of ${fs.items.length}`)),
      el("div", { class: "row small f-filters" }, typeSel, minSel,
        el("label", { class: "f-toggle" }, gone, " withdrawn")));
    if (p.kind === "ara.inspect") {
      box.append(el("p", { class: "muted small" }, "Ctrl-click (⌘-click) a face in the scene to propose a finding there."));
    }
    if (!shown.length) {
      box.append(el("p", { class: "muted small", id: "f-empty" }, fs.items.length ? "none match the filter" : "no findings on this plan"));
      return;
    }
    box.append(el("table", { class: "list small", id: "f-list" }, el("tbody", {}, ...shown.map(row))));
  }

  document.addEventListener("steelpath:selected", (ev) => {
    const p = ev.detail;
    const show = !!p && KINDS.includes(p.kind);
    if (!show) { fs.plan = null; box.hidden = true; box.innerHTML = ""; return; }
    if (!fs.plan || fs.plan.id !== p.id) { fs.items = []; fs.framed = null; }
    fs.plan = p;
    box.hidden = false;
    load();
  });

  let timer = null;
  document.addEventListener("steelpath:finding", (ev) => {
    const d = ev.detail || {};
    if (!fs.plan || d.plan_id !== fs.plan.id) return;
    clearTimeout(timer);
    timer = setTimeout(load, 200);
  });

  // ------------------------------------------- confirming a scene proposal
  // A finding proposal (a Ctrl/Cmd-click on a face) becomes a finding only
  // when an operator says what it is here; the server makes it as
  // POST /findings does.
  window.openFindingForm = (p) => {
    const prev = $("#finding-form");
    if (prev) prev.remove();
    const type = el("select", { name: "type" }, ...typeOptions("corrosion", false));
    const cs = el("select", { name: "condition_state" }, ...csOptions(2, ""));
    const notes = el("textarea", { name: "notes", rows: "3", maxlength: "5000" });
    const err = el("p", { class: "error small" });
    const at = p.patch.point_m ? p.patch.point_m.map((v) => v.toFixed(3)).join(", ") : "";
    const form = el("form", { class: "card" },
      el("h3", {}, "New finding"),
      el("p", { class: "muted small" }, `plan ${p.plan_id}, member ${p.patch.member_id} / face ${p.patch.face_id}, at (${at}) m`),
      el("label", {}, "Type", type), el("label", {}, "Condition state", cs), el("label", {}, "Notes", notes), err,
      el("div", { class: "row" }, el("button", { type: "submit" }, "Create finding"),
        el("button", { type: "button", class: "secondary", onclick: () => overlay.remove() }, "Cancel")));
    const overlay = el("div", { class: "overlay", id: "finding-form" }, form);
    form.addEventListener("submit", async (ev) => {
      ev.preventDefault();
      try {
        const f = await api("POST", `/scene/proposals/${p.id}/accept`,
          { type: type.value, condition_state: Number(cs.value), notes: notes.value });
        overlay.remove();
        flash(`finding ${f.id} (${label(f.type)}, ${f.condition_state} ${CONDITION[f.condition_state]}) on ${f.plan_id}`);
        if (state.selected !== f.plan_id) await select(f.plan_id); else load();
      } catch (e) { err.textContent = e.message; }
      if (typeof loadProposals === "function") loadProposals();
    });
    document.body.append(overlay);
    type.focus();
  };
})();
