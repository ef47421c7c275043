// The web UI's Site page in a real browser (docs/UI.md, "Site"): two vmacd
// hosts (site-a, site-b) on buses of their own, a lights board each, and
// Debian's mosquitto, all started here. Host A's page lists both hosts and
// their lights with values, offers no control, and shows B offline once B
// is killed. Without mosquitto it says SKIPPED (a failure with CI=true).
//
//   node tests/ui/site_test.mjs --bin build/bin --out build/ui
import { spawn, execFileSync } from "node:child_process";
import fs from "node:fs";
import net from "node:net";
import os from "node:os";
import path from "node:path";
import readline from "node:readline";
import { chromium } from "playwright-core";
import { LOADED, args, check, tally, until } from "./common.mjs";

const BIN = path.resolve(args.bin || "build/bin");
const OUT = path.resolve(args.out || "build/ui");
const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";
const MOSQUITTO = ["/usr/sbin/mosquitto", "/usr/bin/mosquitto"].find((p) => fs.existsSync(p));
fs.mkdirSync(OUT, { recursive: true });
const STATE_A = fs.mkdtempSync(path.join(os.tmpdir(), "vmac-site-a-"));
const STATE_B = fs.mkdtempSync(path.join(os.tmpdir(), "vmac-site-b-"));
const rnd = (lo, hi) => lo + Math.floor(Math.random() * (hi - lo + 1));
const bus = () => `239.255.${rnd(1, 254)}.${rnd(1, 254)}:${rnd(20000, 60000)}`;
const procs = [];

if (!MOSQUITTO) {
  const why = "the Site page's test needs Debian's mosquitto (make deps installs it)";
  if (process.env.CI === "true") {
    console.log("FAIL " + why + " (CI=true: a check that cannot run is a failure)");
    process.exit(1);
  }
  console.log("SKIPPED: " + why);
  process.exit(0);
}

function start(name, argv) {
  const p = spawn(argv[0], argv.slice(1), { stdio: ["ignore", "pipe", "pipe"] });
  p.lines = [];
  for (const stream of [p.stdout, p.stderr]) {
    readline.createInterface({ input: stream }).on("line", (line) => {
      p.lines.push(line);
      fs.appendFileSync(path.join(OUT, "site-" + name + ".log"), line + "\n");
    });
  }
  procs.push(p);
  return p;
}


function freePort() {
  return new Promise((resolve) => {
    const s = net.createServer().listen(0, "127.0.0.1", () => {
      const port = s.address().port;
      s.close(() => resolve(port));
    });
  });
}

async function vmacd(name, state, busAddr, brokerPort) {
  const p = start(name, [path.join(BIN, "vmacd"), "--bus", busAddr, "--http", "127.0.0.1:0", "--state", state,
    "--set", "realtime=false", "--set", "slice_us=1250", "--set", "slices_per_slot=5", "--set", "watchdog_ms=1500",
    "--set", "reply_deadline_us=80000", "--set", "discovery_period_ms=300",
    "--set", `mqtt_url=mqtt://127.0.0.1:${brokerPort}`, "--set", `mqtt_host_id=${name}`,
    "--set", `mqtt_client_id=vmac-${name}`, "--set", "mqtt_keepalive_s=5"]);
  const line = await until(() => p.lines.find((l) => /status at http:\/\/\S+\/api\/status/.test(l)), 30000,
    `${name}'s 'status at'`);
  return /status at http:\/\/(\S+)\/api\/status/.exec(line)[1];
}

async function main() {
  const brokerPort = await freePort();
  const conf = path.join(STATE_A, "mosquitto.conf");
  fs.writeFileSync(conf, `listener ${brokerPort} 127.0.0.1\nallow_anonymous true\npersistence false\n`);
  const broker = start("mosquitto", [MOSQUITTO, "-c", conf]);
  await until(() => new Promise((resolve) => {
    const c = net.connect(brokerPort, "127.0.0.1", () => { c.end(); resolve(true); });
    c.on("error", () => resolve(false));
  }), 20000, "mosquitto listening");
  const operate = execFileSync(path.join(BIN, "vmac"), ["token", "create", "--state", STATE_A, "--scope", "operate"])
    .toString().trim();
  const busA = bus(), busB = bus();
  const addrA = await vmacd("site-a", STATE_A, busA, brokerPort);
  await vmacd("site-b", STATE_B, busB, brokerPort);
  // Each host holds its board's key (bus_trust enrolled, the default).
  for (const [name, state, busAddr] of [["lights-a", STATE_A, busA], ["lights-b", STATE_B, busB]]) {
    const keyFile = path.join(state, name + ".key");
    execFileSync(path.join(BIN, "vmac"), ["board", "enroll", name, "--local", "--state", state, "--out", keyFile]);
    start(name, [path.join(BIN, "vmac-board"), "--plant", "lights", "--name", name, "--bus", busAddr,
      "--key-file", keyFile]);
  }
  const hostB = procs.find((p) => p.spawnargs.includes("mqtt_host_id=site-b"));

  const browser = await chromium.launch({
    executablePath: CHROMIUM,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync"],
  });
  try {
    const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
    page.on("pageerror", (e) => { tally.failures++; console.log("FAIL the page raised: " + e.message); });
    const row = (host, device) => `#page-site [data-host="${host}"] tr[data-device="${device}"]`;

    await check("host A's Site page lists both hosts, their lights online with values", async () => {
      await page.goto(`http://${addrA}/#token=${operate}`);
      await page.click('nav a[data-page="site"]');
      for (const [host, device] of [["site-a", "lights-a"], ["site-b", "lights-b"]]) {
        await page.waitForSelector(`${row(host, device)} .badge.online`, { timeout: 30000 * LOADED });
        await page.waitForSelector(`${row(host, device)} [data-name="kitchen"]:has-text("off")`,
          { timeout: 10000 * LOADED });
      }
      await page.waitForSelector('#page-site [data-host="site-a"] h3:has-text("this host")',
        { timeout: 5000 * LOADED });
      await page.screenshot({ path: path.join(OUT, "9-site.png"), fullPage: true });
    });

    await check("the Site page offers no control, even to an operate token", async () => {
      const controls = await page.locator("#page-site button, #page-site input, #page-site select").count();
      if (controls !== 0) throw new Error(`${controls} controls on the Site page`);
    });

    // B's will, which the broker sends 1.5 keep-alives (7.5 s) after B's
    // last packet by its own clock: 30 s leaves a loaded machine room.
    await check("host B killed shows offline on A's Site page once the broker gives up on it", async () => {
      const t0 = performance.now();
      hostB.kill("SIGKILL");
      await page.waitForSelector('#page-site [data-host="site-b"] h3 .badge.offline', { timeout: 30000 * LOADED });
      await page.waitForSelector(`${row("site-b", "lights-b")} .badge.offline`, { timeout: 2000 * LOADED });
      await page.waitForSelector(`${row("site-a", "lights-a")} .badge.online`, { timeout: 2000 * LOADED });
      console.log(`  (B shown offline ${Math.round(performance.now() - t0)} ms after the kill)`);
      await page.screenshot({ path: path.join(OUT, "10-site-b-offline.png"), fullPage: true });
    });
    void broker;
  } finally {
    await browser.close();
  }
}

try {
  await main();
} catch (e) {
  tally.failures++;
  console.log("FAIL the test could not run: " + e.message);
} finally {
  for (const p of procs) p.kill("SIGKILL");
  fs.rmSync(STATE_A, { recursive: true, force: true });
  fs.rmSync(STATE_B, { recursive: true, force: true });
}
console.log(tally.failures ? `${tally.failures} failed (logs and screenshots in ${OUT})` : `every Site check passed (screenshots in ${OUT})`);
process.exit(tally.failures ? 1 : 0);
