// vmac web UI (docs/UI.md): every device live, built from its driver's
// declarations. Plain JavaScript, no build step, served by vmacd itself.
// The token stays in this browser (localStorage) and goes in the
// Authorization header of every call; the status arrives pushed by
// GET /api/live, the latest of it every quarter second. A board's key the
// host makes (Boards) is shown once in the page and kept nowhere. Beside
// it: events.js (the Events page), clock.js (the boards' clocks in a card)
// boards.js (the Boards page) and schedule.js (the System page's time
// manager), loaded before it.
"use strict";

const PLOT_SECONDS = 300;      // plots show the last five minutes
const COLOURS = ["#2563eb", "#f59e0b", "#059669", "#dc2626", "#7c3aed", "#0891b2"];
const CYCLE_VARS = ["state", "cycle", "step", "paused_by", "error", "time_left_s"];
// The appliance's commands (docs/STDLIB.md "appliance") and the cycle states
// in which each is offered; any other command is always offered.
const COMMAND_STATES = {
  start: ["idle", "done", "cancelled", "failed"],
  pause: ["running"],
  resume: ["paused"],
  cancel: ["running", "paused"],
};
const MESSAGES_MAX = 3;        // the message area shows the newest three

const state = {
  token: null,
  scope: "none",
  manifests: {},      // "driver@version" -> manifest (or a promise of it)
  cards: {},          // device name -> card
  chosen: {},         // device name -> the programme the user chose in its card (kept across redraws)
  plotHistory: {},    // device name -> variable -> [[time, value]] (kept across redraws)
  lastEventSeq: 0,
  eventsLoaded: false,
  eventFilter: "all", // the Events page shows every event, the audit trail only, or the rest (events.js)
  status: null,
  stream: null,
  siteTimer: null,    // the Site page's poll while it is shown
  boardsSeen: "",     // what of the status GET /api/boards answers from, when the Boards page last read it
  boardsLoading: null, // the GET /api/boards under way, and whether another is wanted after it
  boardsAgain: false,
  scheduleAt: 0,      // when the System page last had GET /api/schedule's answer (schedule.js)
  scheduleBusy: false,
};

const $ = (sel, root) => (root || document).querySelector(sel);

function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") e.className = v;
    else if (k === "colour") e.style.background = v; // CSSOM: the page's CSP allows no style attributes
    else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else if (v !== undefined && v !== null && v !== false) e.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) {
    if (c !== null && c !== undefined) e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return e;
}

// The one message area (docs/UI.md "Messages"): newest first, at most
// MESSAGES_MAX, each dismissable; the same text again moves to the top
// instead of repeating; news goes after 4 s, a failure stays until it is
// dismissed or the page changes.
function toast(text, bad) {
  const area = $("#messages");
  for (const old of area.querySelectorAll(".toast")) if (old.dataset.text === text) old.remove();
  const t = el("div", { class: "toast" + (bad ? " bad" : ""), role: bad ? "alert" : "status", "data-text": text },
    el("span", {}, text),
    el("button", { class: "dismiss", "aria-label": "dismiss", title: "dismiss", onclick: () => t.remove() }, "\u00d7"));
  area.prepend(t);
  while (area.children.length > MESSAGES_MAX) area.lastChild.remove();
  if (!bad) setTimeout(() => t.remove(), 4000);
}

function clearMessages() {
  $("#messages").replaceChildren();
}

// ---- the API ----

async function api(method, path, body) {
  const opts = { method, headers: { Authorization: "Bearer " + state.token } };
  if (body !== undefined) {
    opts.headers["Content-Type"] = "application/json";
    opts.body = JSON.stringify(body);
  }
  const r = await fetch(path, opts);
  let data = {};
  try { data = await r.json(); } catch (e) { /* an empty answer */ }
  if (r.status === 401) signedOut("the token is not valid (unknown, revoked or malformed)");
  if (!r.ok) {
    const err = new Error(data.error || ("HTTP " + r.status));
    err.status = r.status;
    throw err;
  }
  return data;
}

async function input(device, name, value, persist) {
  try {
    const body = { name };
    if (value !== undefined) body.value = value;
    if (persist) body.persist = true;
    await api("POST", "/api/devices/" + encodeURIComponent(device) + "/input", body);
    if (persist) toast(device + "." + name + " set and kept");
  } catch (e) {
    toast(device + "." + name + ": " + e.message, true);
  }
}

// A driver's manifest for the version a machine runs; nothing is asked
// before that version is known (a machine still attaching has none).
function manifest(driver, version) {
  if (!version) return Promise.resolve({ name: driver, version });
  const key = driver + "@" + version;
  if (!state.manifests[key]) {
    state.manifests[key] = api("GET", "/api/drivers/" + encodeURIComponent(driver) + "/manifest?version=" +
      encodeURIComponent(version)).catch(() => ({ name: driver, version }));
  }
  return state.manifests[key];
}

// ---- sign-in ----

function signedOut(why) {
  clearMessages();
  state.token = null;
  localStorage.removeItem("vmacToken");
  if (state.stream) state.stream.abort();
  siteTimer(false);
  hideKey();
  $("#signin").hidden = false;
  $("#signin-error").textContent = why || "";
  document.querySelectorAll(".page").forEach((p) => { p.hidden = true; });
  $("#signout").hidden = true;
  $("#conn").textContent = "signed out";
  $("#conn").className = "conn down";
}

async function signIn(token) {
  state.token = token;
  try {
    const who = await api("GET", "/api/whoami");
    state.scope = who.scope;
  } catch (e) {
    if (state.token) signedOut(e.message);
    return;
  }
  localStorage.setItem("vmacToken", token);
  $("#signin").hidden = true;
  $("#signout").hidden = false;
  $("#scope").textContent = state.scope === "read" ? "read only" : state.scope;
  document.body.dataset.scope = state.scope;
  showPage();
  live();
}

function mayOperate() {
  return state.scope === "operate" || state.scope === "deploy";
}

// ---- the live status ----

async function live() {
  const ctl = new AbortController();
  state.stream = ctl;
  for (;;) {
    if (ctl.signal.aborted || !state.token) return;
    try {
      const r = await fetch("/api/live", { headers: { Authorization: "Bearer " + state.token }, signal: ctl.signal });
      if (r.status === 401) { signedOut("the token is not valid any more"); return; }
      if (!r.ok) throw new Error("HTTP " + r.status);
      setConn("live");
      const reader = r.body.getReader();
      const dec = new TextDecoder();
      let buf = "";
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buf += dec.decode(value, { stream: true });
        let i;
        while ((i = buf.indexOf("\n\n")) >= 0) {
          const chunk = buf.slice(0, i);
          buf = buf.slice(i + 2);
          const data = chunk.split("\n").filter((l) => l.startsWith("data: ")).map((l) => l.slice(6)).join("\n");
          if (data) onStatus(JSON.parse(data));
        }
      }
    } catch (e) {
      if (ctl.signal.aborted) return;
    }
    setConn("down");
    await new Promise((res) => setTimeout(res, 2000));
  }
}

function setConn(how) {
  $("#conn").textContent = how === "live" ? "live" : "reconnecting";
  $("#conn").className = "conn " + how;
}

function onStatus(s) {
  if (!state.status) $("#empty").textContent = "No devices yet. Plug in a board: its card appears here.";
  state.status = s;
  const now = Date.now() / 1000;
  const seen = new Set();
  for (const d of s.devices) {
    if (d.machine && d.machine !== d.name) continue; // another board of a machine: the primary's card shows it
    if (d.state === "errant") continue;               // dropped: its card goes
    seen.add(d.name);
    const waiting = d.state === "waiting";
    let card = state.cards[d.name];
    if (!card || card.version !== d.driver_version || card.waiting !== waiting) {
      if (card) card.root.remove();
      card = state.cards[d.name] = waiting ? makeWaitingCard(d) : makeCard(d);
    }
    card.update(d, now);
  }
  for (const name of Object.keys(state.cards)) {
    if (!seen.has(name)) removeCard(name);
  }
  $("#empty").hidden = Object.keys(state.cards).length > 0;
  onEvents(s.events || []);
  if (!$("#page-system").hidden) drawSystem(s);
  onBoardsStatus(s);
}

function removeCard(name) {
  const card = state.cards[name];
  delete state.cards[name];
  card.root.classList.add("leaving");
  setTimeout(() => card.root.remove(), 500);
  if (card.waiting) return; // it stopped announcing, or was enrolled: no machine went
  const why = (state.status.events || []).filter((e) => e.device === name && e.kind === "dropped").pop();
  toast(why ? why.text : name + " is gone", true);
}

// ---- a device's card ----

// A variable's name made readable where its driver gave it no label:
// time_left_s -> "Time left (s)", drum_rpm -> "Drum (rpm)", running -> "Running".
const NAME_UNITS = { s: "s", ms: "ms", rpm: "rpm", l: "l", c: "°C", pct: "%", w: "W", kw: "kW", v: "V", a: "A" };
function readable(name) {
  const words = name.split("_").filter(Boolean);
  let unit = "";
  if (words.length > 1 && NAME_UNITS[words[words.length - 1]]) unit = NAME_UNITS[words.pop()];
  const text = words.join(" ");
  return text.charAt(0).toUpperCase() + text.slice(1) + (unit ? " (" + unit + ")" : "");
}

function fmt(v, unit) {
  if (v === null || v === undefined) return "-";
  if (typeof v === "boolean") return v ? "on" : "off";
  if (typeof v === "number") {
    const t = Math.abs(v) >= 100 ? v.toFixed(0) : Math.abs(v) >= 10 ? v.toFixed(1) : v.toFixed(2);
    return unit ? t + " " + unit.replace("degC", "°C") : t;
  }
  return String(v);
}

function clock(seconds) {
  const s = Math.max(0, Math.round(seconds));
  return Math.floor(s / 60) + ":" + String(s % 60).padStart(2, "0");
}

function makeCard(d) {
  const root = el("article", { class: "card", "data-device": d.name },
    el("h2", {}, el("span", { class: "title" }, d.driver), el("span", { class: "badge" }, d.state),
      el("span", { class: "badge sealed", "data-sealed": "", hidden: true,
        title: "its board proved its enrolled key, and every frame with it is sealed" }, "sealed")),
    el("div", { class: "sub" }, d.name + " · " + d.driver + " " + d.driver_version),
    el("div", { class: "clocks", "data-clocks": "", hidden: true })); // its boards' clocks (clock.js)
  $("#cards").append(root);
  const history = state.plotHistory[d.name] = state.plotHistory[d.name] || {};
  const card = { root, version: d.driver_version, parts: null, history, name: d.name, waiting: false };
  card.update = (dev, now) => updateCard(card, dev, now);
  manifest(d.driver, d.driver_version).then((m) => buildCard(card, m));
  return card;
}

// A board waiting for approval (no key this host holds): no driver, no
// values; what to do, and the way to the Boards page.
function makeWaitingCard(d) {
  const note = el("div", { class: "note" });
  const root = el("article", { class: "card waiting", "data-device": d.name, "data-waiting": "" },
    el("h2", {}, el("span", { class: "title" }, d.name), el("span", { class: "badge waiting" }, "waiting")),
    el("div", { class: "sub" }, "driver " + d.driver + " · at " + d.address + " · no driver runs it"),
    note,
    el("a", { class: "button secondary", href: "#boards" }, "Approve it on the Boards page"));
  $("#cards").append(root);
  return { root, version: d.driver_version, name: d.name, waiting: true,
    update: (dev) => { note.textContent = dev.note || "waiting for approval"; } };
}

function buildCard(card, m) {
  const vars = m.variables || {};
  const params = m.params || {};
  const commands = m.commands || {};
  const ui = m.ui || {};
  const operate = mayOperate();
  const device = card.name;
  $(".title", card.root).textContent = ui.title || m.name || "device";
  const parts = { values: {}, toggles: {}, plots: [] };

  const hasCycle = "state" in vars && "step" in vars;
  if (hasCycle) {
    parts.cycle = el("div", { class: "cycle", "data-cycle": "" });
    card.root.append(parts.cycle);
  }
  const list = el("div", { class: "vars" });
  for (const name of Object.keys(vars).sort()) {
    if (hasCycle && CYCLE_VARS.includes(name)) continue;
    const spec = vars[name] || {};
    const value = el("span", { class: "value", "data-var": name });
    parts.values[name] = { el: value, unit: spec.unit };
    let control = null;
    if (operate && spec.set) {
      control = el("button", { class: "secondary", "data-input": name,
        onclick: () => input(device, name, !card.values[name]) }, "Switch");
      parts.toggles[name] = control;
    }
    list.append(el("span", { class: "label" }, spec.label || readable(name)), el("span", {}, value, " ", control));
  }
  card.root.append(list);

  for (const group of ui.plots || []) {
    const names = group.filter((n) => n in vars);
    if (!names.length) continue;
    const canvas = el("canvas", { class: "plot", width: 600, height: 120, "data-plot": names.join(","),
      "data-points": 0 });
    const legend = el("div", { class: "legend" }, names.map((n, i) =>
      el("span", {}, el("i", { colour: COLOURS[i % COLOURS.length] }),
        (vars[n] && vars[n].label) || readable(n))));
    parts.plots.push({ canvas, names });
    card.root.append(canvas, legend);
  }

  if (operate && Object.keys(commands).length) {
    const controls = el("div", { class: "controls" });
    const start = commands.start;
    let programme = null;
    if (start && start.arg && params[start.arg] && params[start.arg].values) {
      programme = el("select", { "aria-label": "programme", "data-param-select": start.arg,
        onchange: () => { state.chosen[device] = programme.value; } },
      params[start.arg].values.map((v) => el("option", { value: v }, v)));
      if (params[start.arg].values.includes(state.chosen[device])) programme.value = state.chosen[device];
      controls.append(programme);
    }
    const order = ["start", "pause", "resume", "cancel"];
    const names = Object.keys(commands).sort((a, b) =>
      ((order.indexOf(a) + 1) || 99) - ((order.indexOf(b) + 1) || 99) || a.localeCompare(b));
    for (const name of names) {
      const spec = commands[name];
      const b = el("button", { "data-command": name, class: name === "cancel" || name === "all_off" ? "danger" : "",
        onclick: () => (name === "start" && programme) ? input(device, name, programme.value) : input(device, name) },
      (spec && spec.label) || name);
      controls.append(b);
      parts.commands = parts.commands || {};
      parts.commands[name] = b;
    }
    parts.programme = programme;
    card.root.append(controls);
  }

  if (operate && Object.keys(params).length) {
    const box = el("details", { class: "settings" }, el("summary", {}, "Settings"));
    for (const name of Object.keys(params).sort()) {
      const spec = params[name] || {};
      let field;
      if (spec.values) {
        field = el("select", { "data-param": name }, spec.values.map((v) => el("option", { value: v }, v)));
      } else if (typeof spec.default === "boolean") {
        field = el("select", { "data-param": name }, el("option", { value: "true" }, "on"),
          el("option", { value: "false" }, "off"));
      } else {
        field = el("input", { type: "number", step: "any", min: spec.min, max: spec.max, "data-param": name });
      }
      const value = () => typeof spec.default === "number" ? Number(field.value)
        : typeof spec.default === "boolean" ? field.value === "true" : field.value;
      field.addEventListener("change", () => { field.dataset.touched = "1"; });
      const send = (persist) => { delete field.dataset.touched; input(device, name, value(), persist); };
      const row = el("div", { class: "setting" },
        el("span", {}, (spec.label || name) + (spec.unit ? " (" + spec.unit + ")" : "")), field,
        el("button", { class: "secondary", "data-set": name, onclick: () => send(false) }, "Set"),
        spec.persist ? el("button", { class: "secondary", "data-keep": name, title: "set, and keep after a restart",
          onclick: () => send(true) }, "Keep") : null);
      parts.params = parts.params || {};
      parts.params[name] = field;
      box.append(row);
    }
    card.root.append(box);
  }
  parts.note = el("div", { class: "note" });
  card.root.append(parts.note);
  card.parts = parts;
  if (card.lastDevice) updateCard(card, card.lastDevice, Date.now() / 1000);
  if (parts.plots.length) loadHistory(card);
}

// The host's recent samples of the plotted variables (docs/API.md
// "GET /api/devices/NAME/history"), so a plot drawn now shows the last
// minutes at once: only what is older than the card's own first point is
// taken, moved to this browser's clock. A machine without history (just
// started) keeps its plots as they are.
async function loadHistory(card) {
  let h;
  try {
    h = await api("GET", "/api/devices/" + encodeURIComponent(card.name) + "/history");
  } catch (e) {
    return;
  }
  const shift = Date.now() / 1000 - h.now;
  for (const [name, values] of Object.entries(h.series || {})) {
    const mine = card.history[name] = card.history[name] || [];
    const before = mine.length ? mine[0][0] : Infinity;
    const older = [];
    h.t.forEach((t, i) => { if (values[i] !== null && t + shift < before) older.push([t + shift, values[i]]); });
    mine.unshift(...older);
  }
  const now = Date.now() / 1000;
  for (const plot of card.parts.plots) drawPlot(plot, card.history, now);
}

function updateCard(card, d, now) {
  card.lastDevice = d;
  card.values = d.variables || {};
  const badge = $(".badge", card.root);
  badge.textContent = d.state;
  badge.className = "badge " + d.state;
  $("[data-sealed]", card.root).hidden = !d.authenticated;
  drawClocks($("[data-clocks]", card.root), state.status, card.name); // clock.js
  const p = card.parts;
  if (!p) return;
  const v = card.values;
  if (p.cycle) {
    const left = v.time_left_s ? " · " + clock(v.time_left_s) + " left" : "";
    p.cycle.replaceChildren(
      el("span", { "data-var": "state" }, fmt(v.state)),
      v.cycle ? " · " + v.cycle : "",
      v.step && v.step !== "-" ? el("span", {}, " · step ", el("span", { class: "step", "data-var": "step" }, v.step)) : "",
      left,
      v.paused_by ? " · paused by " + v.paused_by : "",
      v.error ? el("div", { class: "note" }, v.error) : "");
  }
  for (const [name, part] of Object.entries(p.values)) {
    part.el.textContent = fmt(v[name], part.unit);
    const onoff = typeof v[name] === "boolean";
    part.el.classList.toggle("onoff", onoff); // a lamp, not a word in a line
    part.el.classList.toggle("on", v[name] === true);
  }
  // With a cycle, only the commands its state allows (docs/UI.md "Devices").
  if (p.commands && p.cycle && typeof v.state === "string") {
    for (const [name, b] of Object.entries(p.commands)) {
      if (COMMAND_STATES[name]) b.hidden = !COMMAND_STATES[name].includes(v.state);
    }
    if (p.programme && p.commands.start) p.programme.hidden = p.commands.start.hidden;
  }
  for (const [name, b] of Object.entries(p.toggles)) {
    b.textContent = v[name] ? "Switch off" : "Switch on";
    b.classList.toggle("on", v[name] === true);
  }
  if (p.params) {
    for (const [name, field] of Object.entries(p.params)) {
      if (document.activeElement !== field && d.params && name in d.params && !field.dataset.touched) {
        field.value = String(d.params[name]);
      }
    }
  }
  if (p.programme && d.params && d.params[p.programme.dataset.paramSelect] && !state.chosen[card.name]) {
    p.programme.value = d.params[p.programme.dataset.paramSelect]; // the host's until the user chooses
  }
  p.note.textContent = d.note || "";
  for (const plot of p.plots) {
    for (const name of plot.names) {
      const h = card.history[name] = card.history[name] || [];
      const x = v[name];
      if (typeof x === "number" || typeof x === "boolean") h.push([now, typeof x === "boolean" ? (x ? 1 : 0) : x]);
      while (h.length && h[0][0] < now - PLOT_SECONDS) h.shift();
    }
    plot.onoff = plot.names.every((n) => typeof v[n] === "boolean");
    drawPlot(plot, card.history, now);
  }
}

function drawPlot(plot, history, now) {
  const c = plot.canvas;
  const ctx = c.getContext("2d");
  const w = c.width, hgt = c.height;
  ctx.clearRect(0, 0, w, hgt);
  let lo = Infinity, hi = -Infinity, points = 0, last = null, first = now;
  const onoff = plot.onoff; // booleans: drawn as on/off steps
  for (const n of plot.names) {
    for (const [t, y] of history[n] || []) { lo = Math.min(lo, y); hi = Math.max(hi, y); first = Math.min(first, t); }
  }
  if (lo === Infinity) return;
  // The window: the last minute at least, growing to PLOT_SECONDS.
  const span = Math.min(PLOT_SECONDS, Math.max(60, now - first));
  if (onoff) { lo = -0.1; hi = 1 + 0.12 * plot.names.length; } // on/off lines side by side
  else if (hi - lo < 1e-9) { // a flat series: from zero to it (a flat zero: 0..1), drawn at four fifths
    const v = lo;
    if (v === 0) { lo = 0; hi = 1; } else if (v > 0) { lo = 0; hi = v * 1.25; } else { lo = v * 1.25; hi = 0; }
  }
  c.dataset.lo = lo;
  c.dataset.hi = hi;
  const pad = (hi - lo) * 0.08;
  lo -= pad; hi += pad;
  ctx.fillStyle = "#6b7280";
  ctx.font = "12px system-ui";
  ctx.fillText(onoff ? "on" : fmt(hi - pad), 4, 12);
  ctx.fillText(onoff ? "off" : fmt(lo + pad), 4, hgt - 4);
  ctx.fillText("last " + Math.round(span) + " s", w - 70, hgt - 4);
  plot.names.forEach((n, i) => {
    const h = history[n] || [];
    ctx.strokeStyle = COLOURS[i % COLOURS.length];
    ctx.lineWidth = 2;
    ctx.beginPath();
    const lift = onoff ? i * 0.12 : 0;
    let prev = null;
    h.forEach(([t, y], k) => {
      const px = w - (now - t) / span * w;
      const py = hgt - (y + lift - lo) / (hi - lo) * hgt;
      if (k === 0) ctx.moveTo(px, py);
      else if (onoff && prev !== null) { ctx.lineTo(px, prev); ctx.lineTo(px, py); } // steps for on/off
      else ctx.lineTo(px, py);
      prev = py;
    });
    ctx.stroke();
    points += h.length;
    if (i === 0 && h.length) last = h[h.length - 1][1];
  });
  c.dataset.points = points;
  c.dataset.first = first; // the oldest point's time (this browser's clock, s)
  c.dataset.last = last;
}

// ---- system ----

function drawSystem(s) {
  const lat = s.tick.lateness_us;
  const sch = s.schedule;
  const facts = [
    ["Up", clock(s.uptime_s)],
    ["Slot", sch.slot_us + " µs, " + sch.slices_per_slot + " slices"],
    ["Block", sch.slots_per_block + " slots"],
    ["Capacity used", sch.capacity_used + " of " + sch.capacity_total],
    ["Tick lateness p50 / p99", lat.p50 + " / " + lat.p99 + " µs"],
    ["Tick lateness p99.9 / max", lat.p999 + " / " + lat.max + " µs"],
    ["Ticks", s.tick.count + (s.tick.skipped ? " (" + s.tick.skipped + " skipped)" : "")],
    ["Real-time", s.bus.realtime ? "yes (SCHED_FIFO)" : "no"],
  ];
  $("#system-facts").replaceChildren(...facts.map(([k, v]) => el("div", {}, k, el("b", {}, v))));
  const c = $("#slot-load");
  const ctx = c.getContext("2d");
  const load = sch.slot_load;
  const max = Math.max(1, ...load);
  ctx.clearRect(0, 0, c.width, c.height);
  ctx.fillStyle = "#2563eb";
  const bw = c.width / load.length;
  load.forEach((n, i) => {
    const h = n / max * (c.height - 14);
    ctx.fillRect(i * bw, c.height - h, Math.max(1, bw - (bw > 3 ? 1 : 0)), h);
  });
  ctx.fillStyle = "#374151";
  ctx.font = "12px system-ui";
  ctx.fillText("max " + max + " per slot, " + load.length + " slots", 4, 12);
  const rows = [];
  for (const [k, v] of Object.entries(s.counters)) {
    if (typeof v === "object") {
      for (const [r, n] of Object.entries(v)) if (n) rows.push([k + "." + r, n]);
    } else rows.push([k, v]);
  }
  $("#counters").replaceChildren(...rows.map(([k, v]) => el("tr", {}, el("td", {}, k), el("td", {}, v))));
  loadSchedule(); // schedule.js
}

// ---- site: every host on the broker (GET /api/site), read only ----

const SITE_PERIOD_MS = 1000;

function siteValue(v) {
  if (v === null || v === undefined) return "-";
  if (typeof v === "boolean") return v ? "on" : "off";
  return String(v);
}

function drawSite(site) {
  const note = $("#site-note");
  const hosts = $("#site-hosts");
  if (!site.enabled) {
    note.textContent = "This host has no MQTT broker (mqtt_url is not set): it sees no other host.";
    hosts.replaceChildren();
    return;
  }
  const online = site.hosts.filter((h) => h.state === "online").length;
  note.textContent = site.hosts.length + " host" + (site.hosts.length === 1 ? "" : "s") + " on the broker under " +
    site.prefix + "/, " + online + " online" + (site.connected ? "" : " (this host has lost the broker: " +
    "what it last heard)") + ". Read only: each host is operated from its own page.";
  hosts.replaceChildren(...site.hosts.map(siteHost));
}

function siteDevice(d) {
  const values = Object.entries(d.values).map(([k, v]) => el("span", { "data-name": k }, k, " ", el("b", {}, siteValue(v))));
  return el("tr", { "data-device": d.device },
    el("td", {}, d.device),
    el("td", {}, el("span", { class: "badge " + d.state }, d.state)),
    el("td", {}, el("div", { class: "site-values" }, values)));
}

function siteHost(h) {
  const title = el("h3", {}, h.host, " ", el("span", { class: "badge " + h.state }, h.state),
    h.self ? el("span", { class: "badge" }, "this host") : null);
  if (h.devices.length === 0) return el("div", { class: "site-host", "data-host": h.host }, title,
    el("p", { class: "empty" }, "No devices."));
  const head = el("thead", {}, el("tr", {}, el("th", {}, "Device"), el("th", {}, "State"), el("th", {}, "Values")));
  return el("div", { class: "site-host", "data-host": h.host }, title,
    el("table", { class: "site-devices" }, head, el("tbody", {}, h.devices.map(siteDevice))));
}

async function loadSite() {
  try {
    drawSite(await api("GET", "/api/site"));
  } catch (e) {
    $("#site-note").textContent = "The site view cannot be read: " + e.message;
  }
}

function siteTimer(on) {
  if (state.siteTimer) clearInterval(state.siteTimer);
  state.siteTimer = on ? setInterval(() => { if (state.token) loadSite(); }, SITE_PERIOD_MS) : null;
  if (on) loadSite();
}

// ---- pages ----

function showPage() {
  const page = (location.hash || "#devices").slice(1);
  const name = ["devices", "events", "system", "site", "boards"].includes(page) ? page : "devices";
  document.querySelectorAll(".page").forEach((p) => { p.hidden = p.id !== "page-" + name; });
  document.querySelectorAll("nav a").forEach((a) => a.classList.toggle("active", a.dataset.page === name));
  if (name === "events") loadEvents();
  if (name === "system" && state.status) drawSystem(state.status);
  if (name === "boards") loadBoards();
  siteTimer(name === "site");
}

window.addEventListener("hashchange", () => { clearMessages(); if (state.token) showPage(); });
$("#signin-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  signIn($("#token-input").value.trim());
});
$("#signout").addEventListener("click", () => signedOut(""));
$("#event-filter").addEventListener("change", (ev) => filterEvents(ev.target.value)); // events.js

(function start() {
  // #token=T signs in with T once and leaves the address bar without it.
  const m = /^#token=([^&]+)/.exec(location.hash);
  if (m) {
    localStorage.setItem("vmacToken", decodeURIComponent(m[1]));
    history.replaceState(null, "", location.pathname + "#devices");
  }
  const token = localStorage.getItem("vmacToken");
  if (token) signIn(token); else signedOut("");
})();
