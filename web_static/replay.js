// Replay of a finished run: the recorded timeline of the
// selected plan's execution, scrubbed with a slider; an operator's slider
// moves the replay robot in the scene (POST /scene/replay, throttled).
// Uses console.js's globals: state, api, $, el, flash.
"use strict";

const REPLAY_FINISHED = ["completed", "aborted", "faulted", "interrupted"];
const REPLAY_MIN_MS = 200;  // at most 5 scene requests a second; the last value wins
const REPLAY_MAX_TICKS = 120;  // acknowledgement ticks on the track, at most

const replay = { planId: null, executions: [], tl: null, t: 0, playing: false, speed: 1,
  timer: null, lastSent: 0, inFlight: false, pending: null, sendTimer: null };

function replayCanDrive() { return !!(state.me && state.me.role !== "viewer"); }

async function replayLoad(plan) {
  const box = $("#replay-box");
  replayStop();
  replay.planId = plan ? plan.id : null;
  replay.tl = null;
  if (!plan) { box.hidden = true; box.innerHTML = ""; return; }
  let rows = [];
  try { rows = await api("GET", `/executions?plan_id=${encodeURIComponent(plan.id)}`); } catch { rows = []; }
  if (replay.planId !== plan.id) return;  // another plan was selected meanwhile
  replay.executions = rows.filter((x) => REPLAY_FINISHED.includes(x.state));
  if (!replay.executions.length) { box.hidden = true; box.innerHTML = ""; return; }
  await replayOpen(replay.executions[0].id);
}

async function replayOpen(eid) {
  const planId = replay.planId;
  const tl = await api("GET", `/executions/${encodeURIComponent(eid)}/replay`);
  if (replay.planId !== planId) return;
  replay.tl = tl;
  replay.t = 0;
  replayRender();
}

function replayRender() {
  const box = $("#replay-box");
  const tl = replay.tl;
  box.innerHTML = "";
  box.hidden = false;
  const pick = el("select", { id: "replay-execution", onchange: (e) => replayOpen(e.target.value) });
  for (const x of replay.executions) {
    const o = el("option", { value: x.id }, `${x.id} (${x.state})`);
    if (x.id === tl.execution_id) o.selected = true;
    pick.append(o);
  }
  const dur = Math.max(tl.duration_s, 0.1);
  const slider = el("input", { id: "replay-slider", type: "range", min: "0", max: dur.toFixed(2),
    step: "0.05", value: "0", "aria-label": "replay time (s)" });
  slider.addEventListener("input", () => { replaySet(Number(slider.value), true); });
  const ticks = el("div", { class: "replay-ticks", "aria-hidden": "true" });
  // At most REPLAY_MAX_TICKS acknowledgement ticks: a long program's (571
  // commands) merged into one bar; every step-th is shown, and the last.
  const step = Math.max(1, Math.ceil(tl.acks.length / REPLAY_MAX_TICKS));
  tl.acks.forEach((a, i) => {
    if (i % step !== 0 && i !== tl.acks.length - 1) return;
    ticks.append(el("span", { class: "tick ack", style: `left:${(100 * a.t_s / dur).toFixed(3)}%`,
      title: `${a.t_s.toFixed(1)} s: command ${a.index} (${a.op}) acknowledged`
        + (step > 1 ? ` (a tick every ${step} commands)` : "") }));
  });
  for (const o of tl.operator) {
    if (o.t_s < 0 || o.t_s > dur) continue;
    ticks.append(el("span", { class: "tick op", style: `left:${(100 * o.t_s / dur).toFixed(3)}%`,
      title: `${o.t_s.toFixed(1)} s: ${o.actor} ${o.action} ${o.entity}` }));
  }
  const play = el("button", { id: "replay-play", class: "secondary", onclick: replayToggle }, "Play");
  const speed = el("select", { id: "replay-speed", onchange: (e) => { replay.speed = Number(e.target.value); } },
    el("option", { value: "1" }, "1×"), el("option", { value: "4" }, "4×"));
  speed.value = String(replay.speed);
  const drive = el("input", { id: "replay-drive", type: "checkbox", class: "operator-only" });
  drive.checked = replayCanDrive();
  const clear = el("button", { id: "replay-clear", class: "secondary operator-only", onclick: replayClear },
    "Remove from scene");
  const driveLabel = el("label", { class: "small" }, drive, " show in the scene");
  if (!replayCanDrive()) {
    const why = `the scene is operator-only; ${state.me ? state.me.name : "you"} is a viewer: the timeline reads only`;
    for (const b of [drive, clear]) { b.disabled = true; b.title = why; }
    driveLabel.title = why;
  }
  const thin = tl.thinning.stride > 1 ? ` (${tl.thinning.note})` : "";
  box.append(
    el("h4", {}, "Replay ", pick),
    el("p", { class: "muted small" },
      `${tl.robot}, ${tl.samples.length} recorded states, ${tl.acks.length}/${tl.total} commands acknowledged, ` +
      `${tl.duration_s.toFixed(1)} s${thin}`),
    el("div", { class: "replay-track" }, slider, ticks),
    el("div", { class: "row" }, play, speed, driveLabel, clear,
      el("span", { id: "replay-time", class: "small" }, "")),
    el("p", { class: "small" }, "Executing: ", el("code", { id: "replay-command" }, "–")),
    el("table", { id: "replay-joints", class: "list small" }, el("tbody")),
  );
  replaySet(0, false);
}

// The recorded joints at t: linear between the reports around it (as the server does).
function replayJoints(t) {
  const s = replay.tl.samples;
  if (!s.length) return null;
  let i = 0;
  while (i + 1 < s.length && s[i + 1].t_s <= t) i++;
  const a = s[i].state.q_rad || [];
  if (t <= s[0].t_s || i + 1 >= s.length) return { q: a, st: s[i].state };
  const b = s[i + 1].state.q_rad || [];
  if (a.length !== b.length || s[i + 1].t_s <= s[i].t_s) return { q: a, st: s[i].state };
  const f = (t - s[i].t_s) / (s[i + 1].t_s - s[i].t_s);
  return { q: a.map((v, k) => v + (b[k] - v) * f), st: s[i].state };
}

function replaySet(t, drive) {
  const tl = replay.tl;
  if (!tl) return;
  replay.t = t;
  const slider = $("#replay-slider");
  if (slider && Number(slider.value) !== t) slider.value = String(t);
  $("#replay-time").textContent = `t = ${t.toFixed(1)} s / ${tl.duration_s.toFixed(1)} s`;
  const done = tl.acks.filter((a) => a.t_s <= t).length;
  const ops = tl.program_ops || [];
  $("#replay-command").textContent = done < ops.length ? `#${done} ${ops[done]}` : "all commands done";
  const tb = $("#replay-joints tbody");
  tb.innerHTML = "";
  const j = replayJoints(t);
  if (j) {
    tb.append(el("tr", { class: "q" }, el("th", {}, "q (rad)"), ...j.q.map((v) => el("td", {}, v.toFixed(3)))));
    const extra = [];
    if (j.st.mode !== undefined) extra.push(`mode ${j.st.mode}`);
    if (j.st.odometry_m !== undefined) extra.push(`odometry ${[].concat(j.st.odometry_m).map((v) => Number(v).toFixed(3)).join(", ")} m`);
    if (j.st.faults && j.st.faults.length) extra.push(`faults ${j.st.faults.join(", ")}`);
    if (extra.length) tb.append(el("tr", {}, el("th", {}, "state"), el("td", { colspan: String(j.q.length) }, extra.join("; "))));
  }
  if (drive) replaySend();
}

// Throttled: one request at a time, at most every REPLAY_MIN_MS; the last value wins.
function replaySend() {
  const drive = $("#replay-drive");
  if (!replayCanDrive() || !drive || !drive.checked || !replay.tl) return;
  replay.pending = { execution_id: replay.tl.execution_id, t_s: replay.t };
  if (replay.inFlight || replay.sendTimer) return;
  const wait = REPLAY_MIN_MS - (Date.now() - replay.lastSent);
  if (wait > 0) { replay.sendTimer = setTimeout(() => { replay.sendTimer = null; replaySend(); }, wait); return; }
  const body = replay.pending;
  replay.pending = null;
  replay.inFlight = true;
  replay.lastSent = Date.now();
  api("POST", "/scene/replay", body)
    .catch((e) => { flash(`replay: ${e.message}`, true); })
    .finally(() => {
      replay.inFlight = false;
      if (replay.pending) replaySend();
    });
}

async function replayClear() {
  try { await api("DELETE", "/scene/replay"); flash("replay robot removed from the scene"); }
  catch (e) { flash(`replay: ${e.message}`, true); }
}

function replayToggle() {
  if (replay.playing) { replayStop(); return; }
  if (!replay.tl) return;
  if (replay.t >= replay.tl.duration_s) replay.t = 0;
  replay.playing = true;
  $("#replay-play").textContent = "Pause";
  let last = performance.now();
  replay.timer = setInterval(() => {
    const now = performance.now();
    const t = Math.min(replay.t + ((now - last) / 1000) * replay.speed, replay.tl.duration_s);
    last = now;
    replaySet(t, true);
    if (t >= replay.tl.duration_s) replayStop();
  }, 100);
}

function replayStop() {
  if (replay.timer) clearInterval(replay.timer);
  replay.timer = null;
  replay.playing = false;
  const b = $("#replay-play");
  if (b) b.textContent = "Play";
}

document.addEventListener("steelpath:selected", (e) => { replayLoad(e.detail).catch(console.error); });
document.addEventListener("steelpath:execution", (e) => {
  const d = e.detail || {};
  // A run of the selected plan finished: it can be replayed now.
  if (d.plan_id && d.plan_id === replay.planId && REPLAY_FINISHED.includes(d.state) &&
      !(replay.tl && replay.tl.execution_id === d.id && replay.tl.state === d.state)) {
    const p = state.plans.get(d.plan_id);
    if (p && !replay.playing) replayLoad(p).catch(console.error);
  }
});
