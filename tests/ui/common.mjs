// What the web UI's browser tests share (tests/ui/ui_test.mjs,
// tests/ui/site_test.mjs): their command line, how long they wait, waiting
// for a condition, and checks that count their failures and go on.
export const args = Object.fromEntries(process.argv.slice(2).reduce((acc, a, i, all) =>
  (a.startsWith("--") ? acc.concat([[a.slice(2), all[i + 1]]]) : acc), []));

// Every timeout of these tests bounds what a page or host should do
// promptly; none is a pause. make test runs them beside every other suite
// on two cores, where a page may take several times as long: each bound
// is LOADED times what an idle machine needs (until() applies it too).
export const LOADED = 3;

// failures: how many checks (and page errors) failed so far.
export const tally = { failures: 0 };

// fn's truthy value, asked every 100 ms for LOADED times ms (by the
// monotonic clock: a wall clock set meanwhile neither ends the wait early
// nor makes it last).
export async function until(fn, idleMs, what) {
  const ms = idleMs * LOADED;
  const end = performance.now() + ms;
  for (;;) {
    const v = await fn();
    if (v) return v;
    if (performance.now() > end) throw new Error(`${what}: not within ${ms} ms`);
    await new Promise((r) => setTimeout(r, 100));
  }
}

export async function check(name, fn) {
  try {
    await fn();
    console.log("PASS " + name);
  } catch (e) {
    tally.failures++;
    console.log("FAIL " + name + ": " + (e && e.message ? e.message.split("\n")[0] : e));
  }
}
