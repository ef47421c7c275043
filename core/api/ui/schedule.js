// vmac web UI, the System page's time-manager table (docs/UI.md, "Events
// and System"; docs/SCHEDULER.md, "The static time manager"): GET
// /api/schedule as a table, one line per board served in a row (slot) of
// the longest period in use, with the instants its inputs are latched and
// its outputs released, and its deadline violation vector (replies not in
// time, requests the host failed to send, driver ticks late), a violating
// board marked; then the violations, the latest first. Read at most once a
// second while the page shows. Its rows are marked data-board, never
// data-device (which names a device's card). Loaded before app.js, whose
// el, $, api and state these functions use when they are called.
"use strict";

const SCHEDULE_PERIOD_MS = 1000;
const VIOLATION_WORDS = {
  miss: "a reply not in time",
  miss_host: "a request the host failed to send",
  driver_late: "a driver tick not done by the next service",
};

function scheduleInstant(us) {
  return us === null || us === undefined ? "on arrival" : us + " µs";
}

function scheduleRow(row, e, first) {
  const v = e.violations;
  const cells = [
    el("td", {}, first ? String(row.slot) : ""),
    el("td", {}, first ? row.offset_us + " µs" : ""),
    el("td", {}, e.name),
    el("td", {}, e.machine || "-"),
    el("td", {}, e.pattern),
    el("td", {}, scheduleInstant(e.latch_us)),
    el("td", {}, scheduleInstant(e.release_us)),
    el("td", { class: "num", "data-misses": "" }, String(v.misses)),
    el("td", { class: "num", "data-misses-host": "" }, String(v.misses_host)),
    el("td", { class: "num", "data-driver-late": "" }, String(v.driver_late)),
  ];
  return el("tr", { "data-board": e.name, class: v.last ? "violated" : "" }, ...cells);
}

function drawSchedule(t) {
  const rows = [];
  for (const row of t.timeline) row.devices.forEach((e, i) => rows.push(scheduleRow(row, e, i === 0)));
  $("#schedule-rows").replaceChildren(...rows);
  $("#schedule-note").textContent = t.timeline.length ? t.slots + " rows of " + t.slot_us +
    " µs: the longest period in use." : "No device is in the schedule.";
  const v = t.violated.map((x) => el("li", { "data-board": x.name }, x.name + " (row " + x.slot + "): " +
    (VIOLATION_WORDS[x.kind] || x.kind) + ", " + x.ago_s.toFixed(1) + " s ago"));
  $("#violations").replaceChildren(...v);
  $("#violations-empty").hidden = v.length > 0;
}

// Called with every status while the System page shows: asks for the
// table again once SCHEDULE_PERIOD_MS has passed since the last answer.
async function loadSchedule() {
  const now = Date.now();
  if (state.scheduleBusy || now - (state.scheduleAt || 0) < SCHEDULE_PERIOD_MS) return;
  state.scheduleBusy = true;
  try {
    drawSchedule(await api("GET", "/api/schedule"));
    $("#schedule-error").textContent = "";
  } catch (e) {
    $("#schedule-error").textContent = "The schedule cannot be read: " + e.message;
  } finally {
    state.scheduleAt = Date.now();
    state.scheduleBusy = false;
  }
}
