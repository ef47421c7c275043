// The web UI in a real browser (docs/UI.md): Debian's chromium, headless,
// driven by playwright-core, against vmacd and the four mock boards of the
// demo kitchen (the dryer from examples/kitchen/, its driver read with
// --drivers and its plant in Lua), all started here on a bus of their own. The kitchen's
// boards are enrolled and keyed (bus_trust enrolled, the default); a fifth
// board, started without a key, waits for approval and is enrolled and
// removed through the Boards page.
//
//   node tests/ui/ui_test.mjs --bin build/bin --out build/ui
//
// Prints PASS or FAIL per check and exits 1 when any failed; screenshots of
// every state go to --out for people to look at.
import { spawn, execFileSync } from "node:child_process";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import readline from "node:readline";
import { chromium } from "playwright-core";
import { LOADED, args, check, tally, until } from "./common.mjs";

const BIN = path.resolve(args.bin || "build/bin");
const OUT = path.resolve(args.out || "build/ui");
const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";
const KITCHEN = path.resolve(path.dirname(new URL(import.meta.url).pathname), "..", "..", "examples", "kitchen");
fs.mkdirSync(OUT, { recursive: true });
const STATE = fs.mkdtempSync(path.join(os.tmpdir(), "vmac-ui-"));
const KEYS = path.join(STATE, "keys"); // the boards' key files
const rnd = (lo, hi) => lo + Math.floor(Math.random() * (hi - lo + 1));
const BUS = `239.255.${rnd(1, 254)}.${rnd(1, 254)}:${rnd(20000, 60000)}`;
const procs = [];

function start(name, argv, withStdin) {
  const p = spawn(argv[0], argv.slice(1), { stdio: [withStdin ? "pipe" : "ignore", "pipe", "pipe"] });
  p.lines = [];
  p.waiters = [];
  for (const stream of [p.stdout, p.stderr]) {
    readline.createInterface({ input: stream }).on("line", (line) => {
      p.lines.push(line);
      fs.appendFileSync(path.join(OUT, name + ".log"), line + "\n");
      p.waiters = p.waiters.filter((w) => !w(line));
    });
  }
  procs.push(p);
  return p;
}

function waitLine(p, re, ms, what) {
  return new Promise((resolve, reject) => {
    const found = p.lines.find((l) => re.test(l));
    if (found) return resolve(found);
    const timer = setTimeout(() => reject(new Error(`${what} not seen within ${ms} ms`)), ms);
    p.waiters.push((line) => {
      if (!re.test(line)) return false;
      clearTimeout(timer);
      resolve(line);
      return true;
    });
  });
}

function token(scope) {
  return execFileSync(path.join(BIN, "vmac"), ["token", "create", "--state", STATE, "--scope", scope,
    "--name", "ui-" + scope]).toString().trim();
}

async function status(host, tok) {
  const r = await fetch(`http://${host}/api/status`, { headers: { Authorization: "Bearer " + tok } });
  return r.json();
}

async function boardsOf(host, tok) {
  const r = await fetch(`http://${host}/api/boards`, { headers: { Authorization: "Bearer " + tok } });
  if (!r.ok) throw new Error(`GET /api/boards: HTTP ${r.status}`);
  return r.json();
}


const deviceOut = (s, name, bit) => ((s.devices.find((d) => d.name === name) || {}).outputs || { digital: [] }).digital[bit];

async function main() {
  const operate = token("operate");
  const read = token("read");
  const deploy = token("deploy");
  fs.mkdirSync(KEYS, { mode: 0o700 });
  execFileSync(path.join(BIN, "vmac"), ["board", "enroll", "--local", "--state", STATE, "--key-dir", KEYS,
    "washer-1", "dish-1", "lights-1", "dryer-1"]);
  const host = start("vmacd", [path.join(BIN, "vmacd"), "--bus", BUS, "--http", "127.0.0.1:0", "--state", STATE,
    "--drivers", KITCHEN, "--set", "driver.dryer.param.time_scale=0.05",
    "--set", "realtime=false", "--set", "slice_us=1250", "--set", "slices_per_slot=5", "--set", "watchdog_ms=1500",
    "--set", "reply_deadline_us=80000", "--set", "miss_limit=2", "--set", "discovery_period_ms=300",
    "--set", "driver.washer.param.time_scale=0.05"]);
  const line = await waitLine(host, /status at http:\/\/(\S+)\/api\/status/, 30000, "vmacd's 'status at'");
  const addr = /status at http:\/\/(\S+)\/api\/status/.exec(line)[1];
  const boards = {};
  for (const [plant, name] of [["washer", "washer-1"], ["dishwasher", "dish-1"], ["lights", "lights-1"]]) {
    boards[name] = start(name, [path.join(BIN, "vmac-board"), "--plant", plant, "--name", name, "--bus", BUS,
      "--key-file", path.join(KEYS, name + ".key"), "--commands"], true);
  }
  boards["dryer-1"] = start("dryer-1", [path.join(BIN, "vmac-board"), "--plant-file",
    path.join(KITCHEN, "plants", "dryer.lua"), "--name", "dryer-1", "--bus", BUS,
    "--key-file", path.join(KEYS, "dryer-1.key"), "--commands"], true);

  const browser = await chromium.launch({
    executablePath: CHROMIUM,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync"],
  });
  try {
    const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
    page.on("pageerror", (e) => { tally.failures++; console.log("FAIL the page raised: " + e.message); });
    const manifestAsks = []; // every manifest the page asked for, checked at the end
    page.on("request", (r) => { if (r.url().includes("/manifest")) manifestAsks.push(r.url()); });

    await check("before the first status the page says it is connecting, not that there are no devices", async () => {
      const cp = await browser.newPage();
      await cp.route("**/api/live", (r) => r.abort()); // the status never comes
      await cp.goto(`http://${addr}/#token=${operate}`);
      await cp.waitForSelector("#conn.down", { timeout: 10000 * LOADED });
      const empty = await cp.textContent("#empty");
      if (!/connecting/i.test(empty) || /no devices/i.test(empty)) throw new Error(`the page says: ${empty}`);
      await cp.close();
    });

    await check("four cards appear, and the token leaves the address bar", async () => {
      await page.goto(`http://${addr}/#token=${operate}`);
      for (const name of ["washer-1", "dish-1", "lights-1", "dryer-1"]) {
        await page.waitForSelector(`[data-device="${name}"] [data-var]`, { timeout: 30000 * LOADED });
      }
      // A machine dropped and attached again (a slow start) leaves its old
      // card fading out for half a second: count the cards that stay.
      await page.waitForFunction(() => document.querySelectorAll(".card:not(.leaving)").length === 4 &&
        !document.querySelector(".card.leaving"), null, { timeout: 10000 * LOADED }).catch(() => {});
      const cards = await page.locator(".card:not(.leaving)").count();
      if (cards !== 4) throw new Error(`${cards} cards`);
      if (page.url().includes("token")) throw new Error("the token is still in the address bar: " + page.url());
      await page.screenshot({ path: path.join(OUT, "1-kitchen.png"), fullPage: true });
    });

    await check("an idle machine offers Start and its programme, not Pause, Resume or Cancel", async () => {
      const card = '[data-device="dish-1"]';
      await page.waitForSelector(`${card} [data-command="start"]:visible`, { timeout: 5000 * LOADED });
      await page.waitForSelector(`${card} [data-param-select="program"]:visible`, { timeout: 5000 * LOADED });
      for (const name of ["pause", "resume", "cancel"]) {
        if (await page.isVisible(`${card} [data-command="${name}"]`)) throw new Error(`${name} offered on an idle dishwasher`);
      }
    });

    await check("an unlabelled variable has a readable name and an on/off lamp", async () => {
      const card = '[data-device="washer-1"]';
      await page.waitForSelector(`${card} .vars .label:text-is("Running")`, { timeout: 5000 * LOADED });
      await page.waitForSelector(`${card} [data-var="running"].onoff:text-is("off")`, { timeout: 5000 * LOADED });
      if (await page.locator(`${card} .vars .label:text-is("running")`).count()) throw new Error("a raw name shown");
      await page.waitForSelector('[data-device="lights-1"] [data-var="kitchen"].onoff', { timeout: 5000 * LOADED });
    });

    await check("a flat zero is drawn on a 0..1 axis, not -1..1", async () => {
      const plot = '[data-device="washer-1"] canvas[data-plot^="drum_rpm"]';
      await page.waitForFunction((sel) => {
        const c = document.querySelector(sel);
        return c && Number(c.dataset.points) > 0 && c.dataset.lo !== undefined;
      }, plot, { timeout: 10000 * LOADED });
      const [lo, hi] = await page.$eval(plot, (c) => [Number(c.dataset.lo), Number(c.dataset.hi)]);
      if (lo !== 0 || hi !== 1) throw new Error(`the idle drum's axis is ${lo}..${hi}`);
    });

    await check("messages: one area, the newest three, dismissable, cleared on another page", async () => {
      await page.evaluate(() => { for (let i = 1; i <= 5; i++) toast("failure " + i, true); });
      const shown = await page.locator("#messages .toast").allTextContents();
      if (shown.length !== 3 || !shown[0].startsWith("failure 5")) throw new Error("shown: " + JSON.stringify(shown));
      await page.evaluate(() => toast("failure 5", true));
      if (await page.locator("#messages .toast").count() !== 3) throw new Error("the same message shown twice");
      await page.click("#messages .toast:first-child button.dismiss");
      if (await page.locator("#messages .toast").count() !== 2) throw new Error("dismiss left the message");
      await page.screenshot({ path: path.join(OUT, "1b-messages.png") });
      await page.click('nav a[data-page="system"]');
      await page.waitForSelector("#messages .toast", { state: "detached", timeout: 2000 * LOADED });
      await page.click('nav a[data-page="devices"]');
    });

    await check("the programme chosen in a card is kept when its machine comes back", async () => {
      const card = '[data-device="dish-1"]';
      const options = await page.$$eval(`${card} [data-param-select="program"] option`, (os) => os.map((o) => o.value));
      const current = await page.inputValue(`${card} [data-param-select="program"]`);
      const other = options.find((o) => o !== current);
      if (!other) throw new Error("the dishwasher has one programme only");
      await page.selectOption(`${card} [data-param-select="program"]`, other);
      boards["dish-1"].kill("SIGKILL");
      await page.waitForSelector(card, { state: "detached", timeout: 5000 * LOADED });
      boards["dish-1"] = start("dish-1b", [path.join(BIN, "vmac-board"), "--plant", "dishwasher", "--name", "dish-1",
        "--bus", BUS, "--key-file", path.join(KEYS, "dish-1.key"), "--commands"], true);
      await page.waitForSelector(`${card}:not(.leaving) [data-param-select="program"]`, { timeout: 30000 * LOADED });
      await page.waitForTimeout(1000); // a few statuses, each with the host's own param
      const now = await page.inputValue(`${card}:not(.leaving) [data-param-select="program"]`);
      if (now !== other) throw new Error(`chose ${other}, the card shows ${now} after its machine came back`);
      await page.click('nav a[data-page="system"]'); // the drop's message is not the next check's
      await page.click('nav a[data-page="devices"]');
    });

    await check("the kitchen's boards proved their keys: their cards say sealed", async () => {
      for (const name of ["washer-1", "dish-1", "lights-1", "dryer-1"]) {
        await page.waitForSelector(`[data-device="${name}"] [data-sealed]:not([hidden])`, { timeout: 5000 * LOADED });
      }
    });

    await check("a board's clock shows in its card exactly when the status has one (none while null)", async () => {
      // The live kitchen: whatever the host says of each board's clock now.
      const s = await status(addr, operate);
      await page.waitForTimeout(500); // a status or two after that one
      for (const name of ["washer-1", "dish-1", "lights-1", "dryer-1"]) {
        const d = s.devices.find((x) => x.name === name);
        const shown = await page.locator(`[data-device="${name}"] [data-clock="${name}"]`).count();
        if (!d.clock && shown) throw new Error(`${name}'s clock is null, its card shows one`);
        if (d.clock && !shown) throw new Error(`${name} has a clock (${JSON.stringify(d.clock)}), its card shows none`);
        if (!d.clock && await page.isVisible(`[data-device="${name}"] [data-clocks]`)) {
          throw new Error(`${name}'s card shows an empty clocks line`);
        }
      }
    });

    await clocks(browser, addr, operate);

    await check("the dryer's card, user content: title, temperature in °C, lamps, plots, programmes", async () => {
      const card = '[data-device="dryer-1"]';
      const title = await page.textContent(`${card} .title`);
      if (title !== "Dryer") throw new Error("the dryer's card is titled " + title);
      await page.waitForSelector(`${card} [data-var="temp_c"]:text("°C")`, { timeout: 5000 * LOADED });
      for (const name of ["heater", "drum", "door_open"]) {
        await page.waitForSelector(`${card} [data-var="${name}"].onoff`, { timeout: 5000 * LOADED });
      }
      for (const plot of ["temp_c,target_c", "heater,drum"]) {
        if (!await page.locator(`${card} canvas[data-plot="${plot}"]`).count()) throw new Error("no plot of " + plot);
      }
      const options = await page.$$eval(`${card} [data-param-select="program"] option`, (os) => os.map((o) => o.value));
      if (options.join(",") !== "cotton,delicate") throw new Error("the dryer's programmes: " + options.join(","));
    });

    await check("delicate started in the dryer's card warms its plant up, the heater lamp lit", async () => {
      const card = '[data-device="dryer-1"]';
      await page.selectOption(`${card} [data-param-select="program"]`, "delicate");
      await page.click(`${card} [data-command="start"]`);
      await page.waitForSelector(`${card} [data-var="step"]:text("warm up")`, { timeout: 10000 * LOADED });
      await page.waitForSelector(`${card} [data-var="heater"].onoff:text("on")`, { timeout: 20000 * LOADED });
      await until(async () => {
        const v = (await status(addr, operate)).devices.find((d) => d.name === "dryer-1").variables;
        return v.temp_c > 22;
      }, 30000, "the dryer's air past 22 °C");
      await page.screenshot({ path: path.join(OUT, "3b-dryer-warming.png"), fullPage: true });
      await page.click(`${card} [data-command="cancel"]`);
    });

    await check("switching the kitchen light on in the page turns the board's output on", async () => {
      await page.click('[data-device="lights-1"] [data-input="kitchen"]');
      await until(async () => deviceOut(await status(addr, operate), "lights-1", 0) === true, 5000,
        "lights-1 output 0 on");
      await page.waitForSelector('[data-device="lights-1"] [data-var="kitchen"]:text("on")',
        { timeout: 5000 * LOADED });
      await page.screenshot({ path: path.join(OUT, "2-kitchen-light-on.png") });
    });

    await check("the wall switch pressed on the board shows on the page", async () => {
      boards["lights-1"].stdin.write("lights-1 toggle2 1\n");
      await page.waitForSelector('[data-device="lights-1"] [data-var="dining"]:text("on")', { timeout: 5000 * LOADED });
      await page.screenshot({ path: path.join(OUT, "3-dining-switch.png") });
    });

    await check("a quick wash started in the page shows its step and a moving drum plot", async () => {
      const card = '[data-device="washer-1"]';
      await page.selectOption(`${card} [data-param-select="program"]`, "quick");
      await page.click(`${card} [data-command="start"]`);
      await page.waitForSelector(`${card} [data-var="step"]`, { timeout: 10000 * LOADED });
      await page.waitForFunction((sel) => {
        const c = document.querySelector(sel);
        return c && Number(c.dataset.points) > 20;
      }, `${card} canvas[data-plot^="drum_rpm"]`, { timeout: 20000 * LOADED });
      await until(async () => {
        const v = (await status(addr, operate)).devices.find((d) => d.name === "washer-1").variables;
        return v.step === "wash";
      }, 90000, "the washer washing");
      await page.waitForFunction((sel) => {
        const c = document.querySelector(sel);
        return c && Math.abs(Number(c.dataset.last)) > 10;
      }, `${card} canvas[data-plot^="drum_rpm"]`, { timeout: 20000 * LOADED });
      const step = await page.textContent(`${card} [data-var="step"]`);
      if (step !== "wash") throw new Error("the page shows step " + step);
      // Running: Pause and Cancel, no Start, no Resume.
      for (const [name, offered] of [["start", false], ["pause", true], ["resume", false], ["cancel", true]]) {
        if (await page.isVisible(`${card} [data-command="${name}"]`) !== offered) {
          throw new Error(`${name} ${offered ? "not offered" : "offered"} while washing`);
        }
      }
      await page.screenshot({ path: path.join(OUT, "4-washing.png"), fullPage: true });
    });

    await check("a page opened while it washes draws the drum plot from before it was opened", async () => {
      // The page's own data: points older than the page itself can only
      // come from the host's history (GET /api/devices/NAME/history).
      // When it was opened, by the wall clock the page's Date.now() reads
      // too (performance.timeOrigin is the browser's monotonic clock moved
      // to the wall clock once, and goes wrong when the wall clock steps).
      const opened = Date.now() / 1000;
      const fresh = await browser.newPage({ viewport: { width: 1280, height: 900 } });
      try {
        await fresh.goto(`http://${addr}/#token=${read}`);
        const plot = '[data-device="washer-1"] canvas[data-plot^="drum_rpm"]';
        const got = await fresh.waitForFunction(([sel, opened]) => {
          const c = document.querySelector(sel);
          return c && Number(c.dataset.first) < opened - 2 && Number(c.dataset.points) > 8 &&
            { first: Number(c.dataset.first), opened, points: Number(c.dataset.points) };
        }, [plot, opened], { timeout: 10000 * LOADED }).catch(async () => {
          const c = await fresh.$eval(plot, (e) => ({ ...e.dataset })).catch(() => "no plot");
          throw new Error(`the fresh page's drum plot (opened at ${opened}) has no points from before it was opened: ` +
            JSON.stringify(c));
        });
        const { first, points } = await got.jsonValue();
        console.log(`  the fresh page's drum plot: ${points} points, the oldest ${(opened - first).toFixed(1)} s before it was opened`);
        await fresh.screenshot({ path: path.join(OUT, "4b-fresh-page-history.png"), fullPage: true });
      } finally {
        await fresh.close();
      }
    });

    // How soon the host drops a silent board is the integration tests'
    // (judged by its own timestamps); here, that the page follows the drop.
    await check("stopping the washer board removes its card and says why", async () => {
      const t0 = performance.now();
      boards["washer-1"].kill("SIGKILL");
      await page.waitForSelector('[data-device="washer-1"]', { state: "detached", timeout: 15000 * LOADED });
      console.log(`  (the card went ${Math.round(performance.now() - t0)} ms after the kill)`);
      await page.waitForSelector(".toast", { timeout: 5000 * LOADED });
      await page.screenshot({ path: path.join(OUT, "5-washer-gone.png") });
    });

    await check("the events and system pages", async () => {
      await page.click('nav a[data-page="events"]');
      await page.waitForSelector('#event-rows tr:has(td.kind:text("dropped"))', { timeout: 5000 * LOADED });
      await page.screenshot({ path: path.join(OUT, "6-events.png"), fullPage: true });
      // The drop made a flight recording (docs/RECORDING.md): its event plots the last seconds.
      await page.click('#event-rows tr:has(td.kind:text("recording")) button.show-recording',
        { timeout: 5000 * LOADED });
      await page.waitForFunction(() => {
        const c = document.querySelector("canvas.recording-plot");
        return c && Number(c.dataset.points) > 10 && Number(c.dataset.marks) >= 1;
      }, null, { timeout: 5000 * LOADED });
      await page.screenshot({ path: path.join(OUT, "6b-recording.png"), fullPage: true });
      await page.click('nav a[data-page="system"]');
      await page.waitForSelector("#system-facts div", { timeout: 5000 * LOADED });
      // The time manager (GET /api/schedule): a line per board still served,
      // each with its deadline violation vector in numbers, and either the
      // violations or "No deadline violated".
      await page.waitForSelector('#schedule-rows tr[data-board="lights-1"]', { timeout: 5000 * LOADED });
      const sched = await page.evaluate(() => ({
        rows: [...document.querySelectorAll("#schedule-rows tr")].map((r) => ({
          device: r.dataset.board,
          vector: ["misses", "misses-host", "driver-late"].map((k) => r.querySelector("[data-" + k + "]").textContent),
        })),
        violations: document.querySelectorAll("#violations li").length,
        empty: !document.querySelector("#violations-empty").hidden,
      }));
      const shown = sched.rows.map((r) => r.device).sort();
      for (const name of ["dish-1", "dryer-1", "lights-1"]) {
        if (!shown.includes(name)) throw new Error(`the time manager lacks ${name}: ${JSON.stringify(shown)}`);
      }
      if (shown.includes("washer-1")) throw new Error("the time manager still lists washer-1, which was dropped");
      for (const r of sched.rows) {
        if (!r.vector.every((x) => /^\d+$/.test(x))) throw new Error(`${r.device}'s vector: ${r.vector}`);
      }
      if (sched.empty === sched.violations > 0) {
        throw new Error(`${sched.violations} violations listed, and "No deadline violated" ${sched.empty ? "shown" : "hidden"}`);
      }
      await page.screenshot({ path: path.join(OUT, "7-system.png"), fullPage: true });
    });

    await check("the light switched in the page is in the audit trail, with the token's name", async () => {
      // docs/API.md "Audit trail": the click on the kitchen light above.
      await page.click('nav a[data-page="events"]');
      const row = '#event-rows tr.audit:has(.audit-what:text("lights-1.kitchen:true"))';
      await page.waitForSelector(row, { timeout: 5000 * LOADED });
      const who = await page.textContent(`${row} .audit-who`);
      if (!/^token [0-9a-f]{16} "ui-operate" \(operate\)$/.test(who)) throw new Error("who: " + who);
      const result = await page.textContent(`${row} .audit-result.ok`);
      if (result !== "200") throw new Error("result: " + result);
      // The page's own requests were never refused (no /favicon.ico without a token).
      const refused = await page.locator("#event-rows tr.audit.refused .audit-what").allTextContents();
      if (refused.length) throw new Error("requests of the page refused: " + refused.join(", "));
      await page.selectOption("#event-filter", "audit");
      const others = await page.locator('#event-rows tr:not([hidden]):not([data-kind="audit"])').count();
      const audits = await page.locator('#event-rows tr[data-kind="audit"]:not([hidden])').count();
      if (others !== 0 || audits === 0) throw new Error(`the audit filter shows ${others} other and ${audits} audit rows`);
      await page.screenshot({ path: path.join(OUT, "6c-audit.png"), fullPage: true });
      await page.selectOption("#event-filter", "other");
      if (await page.locator('#event-rows tr[data-kind="audit"]:not([hidden])').count() !== 0)
        throw new Error("audit rows shown with the audit trail filtered out");
      await page.selectOption("#event-filter", "all");
    });

    await check("a read-only token sees no controls and changes nothing", async () => {
      const ro = await browser.newPage({ viewport: { width: 412, height: 915 } }); // a phone
      await ro.goto(`http://${addr}/#token=${read}`);
      await ro.waitForSelector('[data-device="lights-1"] [data-var="kitchen"]', { timeout: 10000 * LOADED });
      const controls = await ro.locator("[data-input], [data-command], [data-param], [data-set], [data-keep]").count();
      if (controls !== 0) throw new Error(`${controls} controls shown to a read token`);
      await ro.screenshot({ path: path.join(OUT, "8-read-only-phone.png"), fullPage: true });
      await ro.close();
    });

    await check("a wrong token is asked to sign in", async () => {
      const bad = await browser.newPage();
      await bad.goto(`http://${addr}/#token=vmac_0000000000000000_${"0".repeat(64)}`);
      await bad.waitForSelector("#signin:not([hidden]) #signin-error:text('not valid')", { timeout: 10000 * LOADED });
      await bad.close();
    });

    await check("no manifest was asked for before its version was known", async () => {
      const empty = manifestAsks.filter((u) => /version=(&|$)/.test(u));
      if (!manifestAsks.length) throw new Error("no manifest asked for at all");
      if (empty.length) throw new Error("asked: " + empty.join(", "));
    });

    await enrollment(browser, page, addr, { operate, deploy });

    await check("the browser's connections were never taken for slow clients (opened ahead, kept alive)", async () => {
      const cut = host.lines.filter((l) => /connections cut off/.test(l));
      if (cut.length) throw new Error("the host said: " + cut.join(" | "));
    });
  } finally {
    await browser.close();
  }
}

// The boards' clocks from a recorded status (the live host's, with clocks
// put in as GET /api/status gives them once boards send TIMED replies;
// docs/API.md), served to a page of its own in place of GET /api/live:
// dish-1 locked, lights-1 in holdover acting on arrival with its bound
// unknown, and a second board of lights-1 (lights-io) locking, shown by
// name in lights-1's card; the washer's clock null: nothing in its card.
async function clocks(browser, addr, tok) {
  await check("a status with clocks: each board's badge, on arrival, bound and offset; none where null", async () => {
    const rec = await status(addr, tok);
    // Each machine running in the copy, whatever the live one was doing
    // when it was taken (a board that just missed is not what is shown).
    const dev = (name) => {
      const d = rec.devices.find((x) => x.name === name);
      if (!d) throw new Error(`${name} is not in the status at all`);
      d.state = "running";
      return d;
    };
    const clock = (state, extra) => Object.assign({ state, on_arrival: false, bound_us: 1.5, offset_s: 3.5,
      latched_at: 12.5, services_timed: 100, services_on_arrival: 0 }, extra);
    dev("dish-1").clock = clock("locked");
    dev("lights-1").clock = clock("holdover", { on_arrival: true, bound_us: null, offset_s: -0.00025 });
    dev("washer-1").clock = null;
    rec.devices.push(Object.assign({}, dev("lights-1"), { name: "lights-io", machine: "lights-1",
      clock: clock("locking", { bound_us: 840 }) }));
    const cp = await browser.newPage({ viewport: { width: 1280, height: 900 } });
    cp.on("pageerror", (e) => { tally.failures++; console.log("FAIL the clocks page raised: " + e.message); });
    await cp.route("**/api/live", (r) => r.fulfill({ status: 200, contentType: "text/event-stream",
      body: "data: " + JSON.stringify(rec) + "\n\n" }));
    try {
      await cp.goto(`http://${addr}/#token=${tok}`);
      const dish = '[data-device="dish-1"] [data-clock="dish-1"]';
      await cp.waitForSelector(`${dish}[data-clock-state="locked"] .badge.clock-locked:text-is("clock locked")`,
        { timeout: 10000 * LOADED })
        .catch(async (e) => { throw new Error(e.message + "; the page shows: " + await shows(cp)); });
      const text = (sel) => cp.textContent(sel).then((t) => t.trim());
      if (await text(`${dish} [data-clock-bound]`) !== "±1.5 µs") throw new Error("dish-1's bound: " +
        await text(`${dish} [data-clock-bound]`));
      if (await text(`${dish} [data-clock-offset]`) !== "offset +3.500 s") throw new Error("dish-1's offset: " +
        await text(`${dish} [data-clock-offset]`));
      if (await cp.locator(`${dish} [data-clock-arrival]`).count()) throw new Error("dish-1 said on arrival");
      if (await cp.locator(`${dish} .clock-board`).count()) throw new Error("a one-board machine names its board");
      if (!/locked/.test(await cp.getAttribute(dish, "title") || "")) throw new Error("dish-1's clock has no title");
      const lights = '[data-device="lights-1"]';
      const own = `${lights} [data-clock="lights-1"][data-clock-state="holdover"]`;
      await cp.waitForSelector(`${own} [data-clock-arrival]:text-is("on arrival")`, { timeout: 5000 * LOADED });
      if (await text(`${own} [data-clock-bound]`) !== "bound unknown") throw new Error("lights-1's unknown bound: " +
        await text(`${own} [data-clock-bound]`));
      if (await text(`${own} [data-clock-offset]`) !== "offset -250 µs") throw new Error("lights-1's offset: " +
        await text(`${own} [data-clock-offset]`));
      const io = `${lights} [data-clock="lights-io"][data-clock-state="locking"]`;
      if (await text(`${io} .clock-board`) !== "lights-io") throw new Error("lights-io not named in lights-1's card");
      if (await text(`${io} [data-clock-bound]`) !== "±840 µs") throw new Error("lights-io's bound: " +
        await text(`${io} [data-clock-bound]`));
      if (await cp.locator('[data-device="lights-io"]').count()) throw new Error("lights-io has a card of its own");
      if (await cp.locator('[data-device="washer-1"] [data-clock]').count() ||
          await cp.isVisible('[data-device="washer-1"] [data-clocks]')) throw new Error("washer-1 shows a null clock");
      await cp.screenshot({ path: path.join(OUT, "3c-clocks.png"), fullPage: true });
    } finally {
      await cp.close();
    }
  });
}

// What a page shows, for a failure's message: its connection, whether it
// asks to sign in, and each card with its state and clocks line.
function shows(p) {
  return p.evaluate(() => {
    const q = (sel) => document.querySelector(sel);
    const cards = [...document.querySelectorAll(".card")].map((c) => c.dataset.device + " (" +
      (c.querySelector(".badge") || {}).textContent + ", clocks: " +
      ((c.querySelector("[data-clocks]") || {}).textContent || "none") + ")");
    return `connection ${q("#conn").textContent}, sign-in ${q("#signin").hidden ? "hidden" : "shown: " +
      q("#signin-error").textContent}, ${cards.length} cards: ${cards.join("; ")}`;
  }).catch((e) => "(the page cannot be read: " + e.message + ")");
}

// A board without a key (shed-light) waits for approval: the operate page
// marks it and cannot enroll it; a deploy page enrolls it, shows the key
// once, the board given that key attaches sealed, and Remove takes it away.
async function enrollment(browser, page, addr, tokens) {
  const SHED = "shed-light";
  let shed = start(SHED, [path.join(BIN, "vmac-board"), "--plant", "lights", "--name", SHED, "--bus", BUS]);
  const dp = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  dp.on("pageerror", (e) => { tally.failures++; console.log("FAIL the deploy page raised: " + e.message); });
  let key = null, fingerprint = null;

  await check("a board without a key shows as waiting, and the Boards page lists it", async () => {
    await page.click('nav a[data-page="devices"]');
    await page.waitForSelector(`.card.waiting[data-device="${SHED}"] .badge.waiting`, { timeout: 10000 * LOADED });
    const vars = await page.locator(`[data-device="${SHED}"] [data-var]`).count();
    if (vars !== 0) throw new Error(`a waiting board's card shows ${vars} variables: it has no driver`);
    await page.waitForSelector("#boards-count:not([hidden]):text('1')", { timeout: 5000 * LOADED });
    await page.screenshot({ path: path.join(OUT, "11-waiting-card.png"), fullPage: true });
    await page.click('nav a[data-page="boards"]');
    await page.waitForSelector(`#boards-waiting tr[data-board="${SHED}"] [data-enroll="${SHED}"]`,
      { timeout: 5000 * LOADED });
    for (const name of ["dish-1", "lights-1"]) {
      await page.waitForSelector(`#boards-enrolled tr[data-board="${name}"] .badge.sealed`, { timeout: 5000 * LOADED });
    }
  });

  await check("Enroll with an operate token says plainly that it needs a deploy token", async () => {
    await page.click(`[data-enroll="${SHED}"]`);
    await page.waitForSelector("#boards-error:has-text('needs a deploy token')", { timeout: 5000 * LOADED });
    if (await page.locator("#board-key [data-key]").count() !== 0) throw new Error("a key shown after a 403");
    const b = await boardsOf(addr, tokens.deploy);
    if (b.enrolled.some((k) => k.board === SHED)) throw new Error(`${SHED} enrolled by an operate token`);
    await page.screenshot({ path: path.join(OUT, "12-enroll-needs-deploy.png"), fullPage: true });
  });

  await check("Enroll with a deploy token shows the key once, with the fingerprint the host lists", async () => {
    await dp.goto(`http://${addr}/#token=${tokens.deploy}`);
    await dp.click('nav a[data-page="boards"]');
    await dp.click(`#boards-waiting [data-enroll="${SHED}"]`, { timeout: 10000 * LOADED });
    // The host stores the key before it answers (a commit to a disk the
    // other suites share): seconds on a loaded machine.
    key = (await (await dp.waitForSelector("#board-key [data-key]", { timeout: 20000 * LOADED })).textContent()).trim();
    if (!/^[0-9a-f]{32}$/.test(key)) throw new Error(`the key shown is not 32 hex digits: ${JSON.stringify(key)}`);
    fingerprint = await dp.getAttribute("#board-key [data-fingerprint]", "data-fingerprint");
    const listed = (await boardsOf(addr, tokens.deploy)).enrolled.find((k) => k.board === SHED);
    if (!listed) throw new Error(`GET /api/boards does not list ${SHED} enrolled`);
    if (listed.fingerprint !== fingerprint) {
      throw new Error(`the page shows fingerprint ${fingerprint}, the host lists ${listed.fingerprint}`);
    }
    await dp.waitForSelector(`#boards-enrolled tr[data-board="${SHED}"] [data-fingerprint="${fingerprint}"]`,
      { timeout: 20000 * LOADED });
    const kept = await dp.evaluate(() => JSON.stringify(Object.assign({}, localStorage, sessionStorage)));
    if (kept.includes(key)) throw new Error("the page stored the key");
    await dp.screenshot({ path: path.join(OUT, "13-enrolled-key.png"), fullPage: true });
  });

  await check("the board given the key shown attaches, sealed", async () => {
    if (!key) throw new Error("no key was shown");
    const file = path.join(KEYS, SHED + ".key");
    fs.writeFileSync(file, key + "\n", { mode: 0o600 });
    shed.kill("SIGKILL");
    shed = start(SHED + "-keyed", [path.join(BIN, "vmac-board"), "--plant", "lights", "--name", SHED, "--bus", BUS,
      "--key-file", file]);
    await page.click('nav a[data-page="devices"]');
    await page.waitForSelector(`.card:not(.waiting)[data-device="${SHED}"] [data-sealed]:not([hidden])`,
      { timeout: 15000 * LOADED });
    await dp.waitForSelector(`#boards-enrolled tr[data-board="${SHED}"] .badge.running`, { timeout: 10000 * LOADED });
    await dp.click("#board-key [data-key-done]");
    await dp.waitForSelector("#board-key", { state: "hidden", timeout: 2000 * LOADED });
    if (await dp.locator("#board-key *").count() !== 0) throw new Error("the key is still in the page after Done");
  });

  await check("Remove (confirmed) takes the key away: gone from the list, the board waits again", async () => {
    dp.once("dialog", (d) => d.accept());
    await dp.click(`#boards-enrolled [data-remove="${SHED}"]`);
    await dp.waitForSelector(`#boards-enrolled tr[data-board="${SHED}"]`,
      { state: "detached", timeout: 5000 * LOADED });
    const b = await boardsOf(addr, tokens.deploy);
    if (b.enrolled.some((k) => k.board === SHED)) throw new Error(`GET /api/boards still lists ${SHED} enrolled`);
    await dp.waitForSelector(`#boards-waiting tr[data-board="${SHED}"]`, { timeout: 10000 * LOADED });
    await page.waitForSelector(`.card.waiting[data-device="${SHED}"]`, { timeout: 10000 * LOADED });
    await dp.screenshot({ path: path.join(OUT, "14-removed.png"), fullPage: true });
  });
  await dp.close();
}

try {
  await main();
} catch (e) {
  tally.failures++;
  console.log("FAIL the test could not run: " + e.message);
} finally {
  for (const p of procs) p.kill("SIGKILL");
  fs.rmSync(STATE, { recursive: true, force: true });
}
console.log(tally.failures ? `${tally.failures} failed (logs and screenshots in ${OUT})` : `every check passed (screenshots in ${OUT})`);
process.exit(tally.failures ? 1 : 0);
