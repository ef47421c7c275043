// vmac web UI, the Events page (docs/UI.md, "Events and System"): the
// host's events newest first, the audit trail's each split into who did
// what from where and what was answered (docs/API.md, "Audit trail"), a
// filter for the audit trail, and a flight recording's last seconds
// plotted. Loaded before app.js, whose state, el, api and toast these
// functions use when they are called.
"use strict";

const BAD_KINDS = ["dropped", "driver_error", "driver_missing", "schedule_full", "machine_full", "rolled_back",
  "reload_refused", "warning", "sleeping", "auth", "removed"];
const GOOD_KINDS = ["attached", "reloaded", "probation_passed", "enrolled"];
// An audit event's text (docs/API.md, "Audit trail"): TYPE by WHO from WHERE: WHAT -> RESULT (WHY).
const AUDIT_RE = /^([a-z]+) by (.+?) from (\S+): (.*) -> (\d{3}|[a-z_]+)(?: \((.*)\))?$/;

// An audit event's parts, each readable at a glance: what was done, by whom
// (the token's id, name and scope), from where, what was asked and what was
// answered. A text of another shape (a window's summary of refusals) as it is.
function auditCell(text) {
  const m = AUDIT_RE.exec(text || "");
  if (!m) return { cell: el("td", { class: "audit" }, el("pre", {}, text)), refused: true };
  const [, type, who, where, what, result, why] = m;
  const refused = !(result === "ok" || /^2/.test(result));
  const cell = el("td", { class: "audit" },
    el("span", { class: "audit-type" }, type), " by ", el("b", { class: "audit-who" }, who), " from ",
    el("code", { class: "audit-where" }, where), ": ", el("code", { class: "audit-what" }, what), " \u2192 ",
    el("span", { class: "audit-result " + (refused ? "refused" : "ok") }, result),
    why ? el("span", { class: "audit-why" }, " (" + why + ")") : "");
  return { cell, refused };
}

function eventShown(kind) {
  return state.eventFilter === "all" || (state.eventFilter === "audit") === (kind === "audit");
}

function eventRow(e) {
  const kind = e.kind;
  let cls = BAD_KINDS.includes(kind) ? "bad" : GOOD_KINDS.includes(kind) ? "good" : "";
  const when = new Date(e.time * 1000).toLocaleTimeString();
  let what = el("td", {}, el("pre", {}, e.text));
  if (kind === "audit") {
    const a = auditCell(e.text);
    what = a.cell;
    cls = "audit" + (a.refused ? " refused" : "");
  }
  const rec = kind === "recording" && /recording (\d+) kept/.exec(e.text || "");
  if (rec) what.append(el("button", { class: "show-recording", "data-recording": rec[1],
    onclick: (ev) => showRecording(rec[1], ev.target.parentNode) }, "Plot the last seconds"));
  return el("tr", { class: cls, "data-seq": e.seq, "data-kind": kind, hidden: !eventShown(kind) },
    el("td", {}, when), el("td", { class: "kind" }, kind), el("td", {}, e.device || ""), what);
}

function filterEvents(value) {
  state.eventFilter = value;
  for (const row of document.querySelectorAll("#event-rows tr")) row.hidden = !eventShown(row.dataset.kind);
}

// A flight recording (docs/RECORDING.md) fetched and its last seconds
// plotted: the first board's digital outputs as on/off steps and its pwm,
// with the misses, the error and the drop marked; a link saves the file.
const RECORDING_PLOT_S = 10;

async function showRecording(id, cell) {
  try {
    const r = await fetch("/api/recordings/" + id, { headers: { Authorization: "Bearer " + state.token } });
    if (!r.ok) throw new Error("HTTP " + r.status);
    const text = await r.text();
    const lines = text.trim().split("\n").map((l) => JSON.parse(l));
    const ticks = lines.filter((l) => l.tick), marks = lines.filter((l) => l.event && ["miss", "error", "drop"].includes(l.event));
    const end = lines.filter((l) => l.t !== undefined).reduce((m, l) => Math.max(m, l.t), 0) / 1e9;
    const canvas = el("canvas", { class: "plot recording-plot", width: 600, height: 160 });
    const ctx = canvas.getContext("2d");
    const x = (t) => 600 * (1 - (end - t) / RECORDING_PLOT_S);
    const shown = ticks.filter((l) => l.t / 1e9 >= end - RECORDING_PLOT_S);
    for (let bit = 0; bit < 7; bit++) { // digital outputs, a lane each
      ctx.strokeStyle = ["#2563eb", "#16a34a", "#d97706", "#9333ea", "#dc2626", "#0891b2", "#4b5563"][bit];
      ctx.beginPath();
      shown.forEach((l, i) => {
        const y = 150 - bit * 20 - (((l.tick[0].out[0] >> bit) & 1) ? 12 : 0);
        if (i === 0) ctx.moveTo(x(l.t / 1e9), y); else ctx.lineTo(x(l.t / 1e9), y);
      });
      ctx.stroke();
    }
    ctx.fillStyle = "#dc2626";
    for (const m of marks) ctx.fillRect(x(m.t / 1e9) - 1, 0, 2, 160);
    canvas.dataset.points = shown.length;
    canvas.dataset.marks = marks.length;
    const url = URL.createObjectURL(new Blob([text], { type: "application/x-ndjson" }));
    cell.append(el("p", {}, shown.length + " ticks of the last " + RECORDING_PLOT_S + " s (outputs do0.. as lanes; red: miss, error, drop). ",
      el("a", { href: url, download: "recording-" + id + ".vrec" }, "Save the file"),
      " and replay it: vmac test --replay recording-" + id + ".vrec"), canvas);
  } catch (err) {
    toast("recording " + id + ": " + err.message, true);
  }
}

async function loadEvents() {
  if (state.eventsLoaded) return;
  state.eventsLoaded = true;
  const newest = state.lastEventSeq;
  try {
    const log = await api("GET", "/api/events/log?after=" + Math.max(0, newest - 300) + "&limit=300");
    const rows = $("#event-rows");
    for (const e of log.events) {
      if (!rows.querySelector('[data-seq="' + e.seq + '"]')) rows.prepend(eventRow(e));
    }
  } catch (e) {
    toast("events: " + e.message, true);
  }
}

function onEvents(events) {
  const rows = $("#event-rows");
  for (const e of events) {
    if (e.seq <= state.lastEventSeq) continue;
    if (state.lastEventSeq && ["driver_error", "rolled_back", "reloaded", "reload_refused"].includes(e.kind)) {
      toast(e.text, e.kind !== "reloaded");
    }
    state.lastEventSeq = e.seq;
    if (!rows.querySelector('[data-seq="' + e.seq + '"]')) rows.prepend(eventRow(e));
  }
}

