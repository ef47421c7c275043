// vmac web UI, the Boards page (docs/UI.md, "Boards"): who may speak on
// the bus (GET /api/boards), the boards waiting for approval and those
// enrolled, enrolling and removing them (scope deploy), and a key the host
// made shown once in the page and kept nowhere. Loaded before app.js, whose
// state, $, el, api, toast and mayOperate these functions use when they are
// called.
"use strict";

// What of the status the Boards page depends on: each device's state and
// proof, and the enrolling and removing events.
function boardsKey(s) {
  const devices = s.devices.map((d) => d.name + ":" + d.state + ":" + (d.authenticated ? 1 : 0)).join(",");
  const events = (s.events || []).filter((e) => ["enrolled", "removed", "waiting"].includes(e.kind))
    .map((e) => e.seq).join(",");
  return devices + "|" + events;
}

function onBoardsStatus(s) {
  const waiting = s.devices.filter((d) => d.state === "waiting").length;
  $("#boards-count").textContent = waiting;
  $("#boards-count").hidden = waiting === 0;
  const key = boardsKey(s);
  if (!$("#page-boards").hidden && key !== state.boardsSeen) loadBoards();
}

// GET /api/boards and draw it; one at a time, and once more when asked
// again while one is under way.
async function loadBoards() {
  if (state.boardsLoading) { state.boardsAgain = true; return; }
  state.boardsSeen = state.status ? boardsKey(state.status) : "";
  state.boardsLoading = api("GET", "/api/boards");
  try {
    drawBoards(await state.boardsLoading);
  } catch (e) {
    $("#boards-error").textContent = "The boards cannot be read: " + e.message;
  } finally {
    state.boardsLoading = null;
    if (state.boardsAgain) { state.boardsAgain = false; loadBoards(); }
  }
}

function drawBoards(b) {
  const operate = mayOperate();
  $("#boards-note").textContent = (b.bus_trust === "open"
    ? "bus_trust is open: a board without a key attaches too, and anyone on the bus segment can speak as a board. "
    : "Only the boards enrolled here (their key held by this host) get a driver; another board waits for approval. ") +
    (operate ? "Enrolling and removing need a token of scope deploy." : "This token is read only: it lists the boards.");
  // A board enrolled a moment ago goes on being listed as waiting until its
  // unkeyed announcements stop: it waits for its key, in the Enrolled list.
  const enrolledNames = new Set(b.enrolled.map((k) => k.board));
  const held = b.waiting.filter((w) => !enrolledNames.has(w.board));
  const waiting = $("#boards-waiting tbody");
  waiting.replaceChildren(...held.map((w) => el("tr", { "data-board": w.board },
    el("td", {}, w.board), el("td", {}, w.driver), el("td", {}, w.address), el("td", { class: "sub" }, w.note),
    el("td", {}, operate ? el("button", { "data-enroll": w.board, onclick: (ev) => enroll(w.board, ev.target) },
      "Enroll") : null))));
  $("#boards-waiting").hidden = held.length === 0;
  $("#boards-waiting-empty").hidden = held.length > 0;
  const enrolled = $("#boards-enrolled tbody");
  enrolled.replaceChildren(...b.enrolled.map((k) => el("tr", { "data-board": k.board },
    el("td", {}, k.board),
    el("td", {}, el("code", { "data-fingerprint": k.fingerprint }, k.fingerprint)),
    el("td", {}, el("span", { class: "badge " + (k.state || "absent") },
      !k.state ? "not on the bus" : k.state === "waiting" ? "waiting for its key" : k.state),
      k.authenticated ? el("span", { class: "badge sealed", title: "it proved its key" }, "sealed") : null),
    el("td", {}, new Date(k.created * 1000).toLocaleString()),
    el("td", {}, k.note),
    el("td", {}, operate ? el("button", { class: "danger", "data-remove": k.board,
      onclick: (ev) => removeBoard(k.board, ev.target) }, "Remove") : null))));
  $("#boards-enrolled").hidden = b.enrolled.length === 0;
  $("#boards-enrolled-empty").hidden = b.enrolled.length > 0;
}

// What a refused enroll or remove says: a 403 is the token's scope.
function boardsRefused(what, e) {
  $("#boards-error").textContent = e.status === 403
    ? what + " needs a deploy token: this page is signed in with a token of scope " + state.scope +
      ". Make one on the host (vmac token create --scope deploy), sign out and sign in with it."
    : what + ": " + e.message;
}

async function enroll(board, button) {
  button.disabled = true;
  $("#boards-error").textContent = "";
  try {
    showKey(await api("POST", "/api/boards/" + encodeURIComponent(board)));
  } catch (e) {
    boardsRefused("Enrolling " + board, e);
  } finally {
    button.disabled = false;
    loadBoards();
  }
}

async function removeBoard(board, button) {
  if (!confirm("Remove " + board + "'s key? If it runs it is dropped at once (its outputs go safe), " +
    "and from then on it waits for approval.")) return;
  button.disabled = true;
  $("#boards-error").textContent = "";
  try {
    await api("POST", "/api/boards/" + encodeURIComponent(board) + "/remove");
    toast(board + "'s key removed");
  } catch (e) {
    boardsRefused("Removing " + board, e);
  } finally {
    button.disabled = false;
    loadBoards();
  }
}

// The key the host made, shown in the page this once: not in localStorage,
// not in state; "Done" (or signing out) takes it out of the page.
function showKey(r) {
  hideKey();
  const box = $("#board-key");
  if (!r.key) { // a key given by the caller: nothing to hand over
    toast(r.board + " enrolled, key " + r.fingerprint);
    return;
  }
  const file = r.board + ".key";
  const code = el("code", { class: "key", "data-key": "" }, r.key);
  const saved = URL.createObjectURL(new Blob([r.key + "\n"], { type: "text/plain" }));
  box.dataset.url = saved;
  box.dataset.board = r.board;
  box.append(
    el("h3", {}, r.board + " is enrolled: give it this key now"),
    el("p", {}, "It is shown only now: the host keeps it for the bus and never shows it again, and this page keeps " +
      "no copy. Lost, it is replaced by enrolling the board again with a new key (vmac board enroll " + r.board +
      " --replace)."),
    el("div", { class: "key-line" }, code,
      el("button", { class: "secondary", "data-copy": "", onclick: () => copyKey(code) }, "Copy"),
      el("a", { class: "button secondary", href: saved, download: file }, "Save as " + file)),
    el("p", {}, "Key fingerprint ", el("code", { "data-fingerprint": r.fingerprint }, r.fingerprint),
      " (what the Enrolled list shows)."),
    el("p", {}, "Give this key to the board: put this text in a file FILE (", el("code", {}, file),
      ", chmod 600), then"),
    el("ul", {},
      el("li", {}, "a board run by vmac-board: ", el("code", {}, "vmac-board --name " + r.board + " --key-file " + file +
        " ...")),
      el("li", {}, "a Cortex-M3 board's firmware image: ",
        el("code", {}, "scripts/qemu-board-config.py IMAGE -o OUT --key-file " + file))),
    el("p", {}, "and restart it: it attaches when it proves the key."),
    el("button", { "data-key-done": "", onclick: hideKey }, "Done: the board has its key"));
  box.hidden = false;
}

function hideKey() {
  const box = $("#board-key");
  if (box.dataset.url) URL.revokeObjectURL(box.dataset.url);
  delete box.dataset.url;
  delete box.dataset.board;
  box.replaceChildren();
  box.hidden = true;
}

// To the clipboard where the page may write it (https, or localhost), else
// selected for Ctrl+C.
async function copyKey(code) {
  try {
    await navigator.clipboard.writeText(code.textContent);
    toast("the key is copied");
    return;
  } catch (e) { /* no clipboard here: select it instead */ }
  const range = document.createRange();
  range.selectNodeContents(code);
  getSelection().removeAllRanges();
  getSelection().addRange(range);
  let copied = false;
  try { copied = document.execCommand("copy"); } catch (e) { /* not allowed */ }
  toast(copied ? "the key is copied" : "the key is selected: copy it with Ctrl+C (or a long press)");
}
