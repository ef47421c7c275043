// vmac web UI, the boards' clocks in a machine's card (docs/UI.md,
// "Devices"; docs/TIME.md): for every board of the machine that has sent a
// TIMED reply (its devices[].clock not null, API.md "GET /api/status"), a
// badge of its clock's state, "on arrival" when its last service fell back
// to acting on arrival, its error bound and its offset; nothing for a board
// whose clock is null. Loaded before app.js, whose el these functions use
// when they are called.
"use strict";

const CLOCK_STATES = ["unsynced", "locking", "locked", "holdover", "lost"];
const CLOCK_WORDS = {
  unsynced: "its clock is not synchronised to the host's yet",
  locking: "its clock is locking onto the host's",
  locked: "its clock is locked to the host's",
  holdover: "its clock runs on its own estimate: the host's SYNC frames stopped coming",
  lost: "its clock lost the host's: it cannot act at the host's instants",
};

// A duration in seconds as people read it: µs below a millisecond, ms
// below a second, s above.
function clockSeconds(s) {
  const a = Math.abs(s);
  if (a < 1e-3) return (s * 1e6).toFixed(a < 1e-5 ? 1 : 0) + " µs";
  if (a < 1) return (s * 1e3).toFixed(a < 1e-2 ? 2 : 1) + " ms";
  return s.toFixed(a < 100 ? 3 : 1) + " s";
}

// The boards of the machine whose card is named name (its primary board,
// then its others, as the status lists them) that have a clock.
function clockBoards(status, name) {
  return ((status && status.devices) || []).filter((d) =>
    (d.name === name || d.machine === name) && d.clock && typeof d.clock === "object");
}

// One board's clock: its badge (and "on arrival"), bound and offset; the
// board's name before them when the machine has several boards.
function clockItem(d, named) {
  const c = d.clock;
  const st = CLOCK_STATES.includes(c.state) ? c.state : "unsynced";
  const bound = typeof c.bound_us === "number" ? "±" + clockSeconds(c.bound_us / 1e6) : "bound unknown";
  const offset = typeof c.offset_s === "number" ? "offset " + (c.offset_s >= 0 ? "+" : "") + clockSeconds(c.offset_s)
    : "";
  const title = (named ? d.name + ": " : "") + CLOCK_WORDS[st] +
    (c.on_arrival ? "; its last service was acted on arrival, not at the host's instants" : "") +
    (typeof c.bound_us === "number" ? "; estimated error within " + clockSeconds(c.bound_us / 1e6) : "") +
    (offset ? "; its clock less the host's: " + clockSeconds(c.offset_s) : "");
  return el("span", { class: "clock", "data-clock": d.name, "data-clock-state": st, title },
    named ? el("span", { class: "clock-board" }, d.name) : null,
    el("span", { class: "badge clock-" + st }, "clock " + st),
    c.on_arrival ? el("span", { class: "badge clock-arrival", "data-clock-arrival": "" }, "on arrival") : null,
    el("span", { class: "clock-bound", "data-clock-bound": "" }, bound),
    offset ? el("span", { class: "clock-offset", "data-clock-offset": "" }, offset) : null);
}

// The card's clocks line (box) from the status: hidden when no board of
// its machine has a clock.
function drawClocks(box, status, name) {
  const boards = clockBoards(status, name);
  const named = boards.length > 1 || (boards.length === 1 && boards[0].name !== name);
  box.replaceChildren(...boards.map((d) => clockItem(d, named)));
  box.hidden = boards.length === 0;
}
