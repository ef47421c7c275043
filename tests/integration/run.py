#!/usr/bin/env python3
"""Integration test runner: runs every test_* function of
tests/integration/test_*.py against the real programs, each with fresh
processes on its own bus, and kills whatever a test started however it ends.

    python3 tests/integration/run.py --bin build/bin [--filter NAME ...] [-j N]

Tests run N at a time (default 4: they mostly wait on the programs they
start, and each has its own bus, ports and state folder), each in a worker
process of its own, forked from the runner; a test file that must have the
machine to itself says SERIAL = True and its tests run one at a time after
the others. Against a
sanitized build (make test-asan's second pass) the tests marked
harness.plain_pass_only are not run and are listed as PLAIN; with
--plain-pass (make test's plain pass) only those and the tests marked
harness.plain_pass_too run, the rest once in the sanitizer pass. The longest
start first, by how long each passed in the last run of the same build
that timed it (integration-times.json beside the --bin folder when that is
inside build/: build/ for build/bin, build/asan/ for build/asan/bin; every
run updates its own); a test that build has no time for takes the plain
build's, else what the test says with harness.takes_about (a fresh clone,
as CI's, has no times at all), else keeps its file order: a long test
started last kept the others waiting for it.

Prints one PASS/FAIL/SKIP line per test and ends with the longest tests
(LONGEST of them, slowest first, with the CPU each used, and the sums of
every test's time and CPU against the run's own time) and 'N passed, N
failed, N skipped'; the exit code is 1 when
any test failed. A failed test keeps its programs' output in the log
directory its FAIL line names.

A test that cannot run on this machine raises harness.Skip(reason) (e.g. one
that needs root for a mount namespace). It is printed as SKIP with a banner,
listed again at the end, and appended to the file $VMAC_SKIP_FILE when that
is set (make test prints every skipped suite at its end). With CI=true in the
environment a skip is a failure: a CI run must not pass what it did not run."""

import argparse
import glob
import json
import selectors
import importlib.util
import os
import resource
import shutil
import signal
import sys
import tempfile
import time
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.dont_write_bytecode = True  # no __pycache__ in the source tree

import harness  # noqa: E402


class TestTimeout(Exception):
    pass


def on_alarm(signum, frame):
    raise TestTimeout("the test did not finish within its time limit")


STOPS = {signal.SIGTERM, signal.SIGINT}  # what interrupts the runner and its workers
STOP_S = 30  # an interrupted worker's time to clean up before it is killed


def on_terminate(signum, frame):
    raise KeyboardInterrupt("runner got signal %d" % signum)


def collect(name_filter):
    """(name, function, serial) of every test of the test_*.py files here
    whose name holds one of the texts of name_filter (none: every test), in
    file order then definition order; serial: its file says SERIAL = True."""
    tests = []
    for path in sorted(glob.glob(os.path.join(HERE, "test_*.py"))):
        module_name = os.path.splitext(os.path.basename(path))[0]
        spec = importlib.util.spec_from_file_location(module_name, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        found = [
            (fn.__code__.co_firstlineno, name[len("test_"):], fn)
            for name, fn in vars(module).items()
            if name.startswith("test_") and callable(fn) and getattr(fn, "__module__", None) == module_name
        ]
        serial = bool(getattr(module, "SERIAL", False))
        tests += [(name, fn, serial) for _, name, fn in sorted(found)]
    return [t for t in tests if not name_filter or any(f in t[0] for f in name_filter)]


def reason_of(exc):
    """A one-line reason: the assertion's message, or the error and where."""
    if isinstance(exc, AssertionError) and str(exc):
        text = str(exc)
    else:
        frames = traceback.extract_tb(exc.__traceback__)
        in_tests = [f for f in frames if os.path.basename(f.filename).startswith("test_")]
        where = (in_tests or frames)[-1]
        text = "%s: %s (at %s:%d: %s)" % (type(exc).__name__, exc, os.path.basename(where.filename), where.lineno,
                                          where.line)
    return " | ".join(text.splitlines())


def run_one(name, fn, bindir, limit_s, keep):
    """Run one test; returns (outcome, reason), outcome "pass", "fail" or
    "skip"."""
    logdir = tempfile.mkdtemp(prefix="vmac-it-%s-" % name)
    ctx = harness.Context(bindir, logdir)
    failure = skipped = None
    signal.alarm(int(limit_s))
    try:
        fn(ctx)
    except harness.Skip as e:
        skipped = str(e) or "no reason given"
    except Exception as e:  # every failure (TestTimeout too) is reported, none escapes
        failure = reason_of(e)
    finally:
        signal.alarm(0)
        report = ctx.cleanup()
    if report:
        failure = "%s%ssanitizer report from %s" % (failure or "", "; " if failure else "", report)
    if failure:
        return "fail", "%s [logs: %s]" % (failure, logdir)
    if keep:
        return ("skip", skipped) if skipped else ("pass", " [logs: %s]" % logdir)
    shutil.rmtree(logdir, ignore_errors=True)
    if skipped:
        return "skip", skipped
    return "pass", ""


def run_forked(name, fn, bindir, limit_s, keep, out_fd):
    """In a child forked from the runner: run the one test fn, in a session
    of its own (an interrupted runner sends it SIGTERM, whose handler ends
    the test: its cleanup kills what it started), and write its result to out_fd as one JSON line (the runner prints the
    report); never returns. Forked, not started afresh: the runner has
    Python, the harness and every test file loaded already, where a new
    interpreter took 0.2 CPU s to get there, in each of a pass's 240
    tests."""
    code = 1
    try:
        os.setsid()
        os.dup2(out_fd, 1)
        os.close(out_fd)
        signal.signal(signal.SIGALRM, on_alarm)
        signal.signal(signal.SIGTERM, on_terminate)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPS)  # blocked by the runner across the fork
        t0 = time.monotonic()
        outcome, reason = run_one(name, fn, bindir, limit_s, keep)
        took = time.monotonic() - t0
        cpu, sys_cpu = cpu_seconds()
        print(json.dumps({"name": name, "outcome": outcome, "reason": reason, "took": took, "cpu": cpu,
                          "sys": sys_cpu}), flush=True)
        code = 0
    except KeyboardInterrupt:  # the runner interrupted: what the test started is killed by now
        pass
    except BaseException:  # the runner reports a worker without a result, after this
        traceback.print_exc()
    finally:
        os._exit(code)


def cpu_seconds():
    """CPU seconds (user and system), and of them the system's, of this
    worker and of every program its test started (each reaped by the test's
    cleanup): on the 2-core machine make test runs on, the suite's CPU is
    what the tests beside a test wait for."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    sys_cpu = own.ru_stime + children.ru_stime
    return own.ru_utime + children.ru_utime + sys_cpu, sys_cpu


BUILD_DIR = os.path.normpath(os.path.join(HERE, "..", "..", "build"))
PLAIN_TIMES_FILE = os.path.join(BUILD_DIR, "integration-times.json")
UNKNOWN_S = 5.0  # where a test with no time yet goes in the order: about the median
LONGEST = 15     # the longest tests the summary lists, and the most CPU-hungry


def times_file(bindir):
    """Where the times of the tests run against bindir are kept: beside it
    when it is inside build/ (build/asan/bin: build/asan/), else build/.
    A sanitized build's tests take other times than the plain build's
    (three times as long, or less where the ASan pass runs less of them)."""
    parent = os.path.dirname(os.path.normpath(bindir))
    inside = parent == BUILD_DIR or parent.startswith(BUILD_DIR + os.sep)
    return os.path.join(parent, "integration-times.json") if inside else PLAIN_TIMES_FILE


def load_times(path):
    """{test name: seconds it took to pass} of earlier runs, or {}."""
    try:
        with open(path) as f:
            times = json.load(f)
        return {k: float(v) for k, v in times.items()} if isinstance(times, dict) else {}
    except (OSError, ValueError, TypeError, AttributeError):
        return {}


def save_times(path, times):
    """Keep times for the next run's order; nothing if its folder is not there."""
    if not os.path.isdir(os.path.dirname(path)):
        return
    tmp = path + ".tmp"
    try:
        with open(tmp, "w") as f:
            json.dump(times, f, indent=0, sort_keys=True)
        os.replace(tmp, path)
    except OSError:
        pass


def expected_times(tests, own, plain):
    """{test name: seconds expected} for the order: the time of the last run
    of this build, else of the plain build, else harness.takes_about's."""
    expected = {}
    for name, fn, _ in tests:
        for source in (own.get(name), plain.get(name), getattr(fn, "takes_about", None)):
            if source is not None:
                expected[name] = float(source)
                break
    return expected


def longest_report(took, cpu, sys_cpu, wall_s, jobs):
    """The summary's lines on the longest tests: the LONGEST slowest with
    the CPU each used, and the sum of every test's time and CPU against
    the run's own time (what -j bought, and what the machine had to give);
    then the LONGEST that used the most CPU, with the system's part of it
    (what to make cheaper when the suite waits for the CPU)."""
    if not took:
        return []
    lines = ["the %d longest of %d tests (%.0f s of tests and %.0f s of CPU, %.0f s of it the system's, "
             "in %.0f s at -j %d):" % (min(LONGEST, len(took)), len(took), sum(took.values()), sum(cpu.values()),
                                       sum(sys_cpu.values()), wall_s, jobs)]
    for name, seconds in sorted(took.items(), key=lambda kv: (-kv[1], kv[0]))[:LONGEST]:
        lines.append("  %6.1f s  %6s s CPU  %s" % (seconds, "%.1f" % cpu[name] if name in cpu else "?", name))
    if cpu:
        lines.append("the %d that used the most CPU:" % min(LONGEST, len(cpu)))
        for name, seconds in sorted(cpu.items(), key=lambda kv: (-kv[1], kv[0]))[:LONGEST]:
            lines.append("  %6.1f s CPU (%5.1f s system)  %s" % (seconds, sys_cpu.get(name, 0.0), name))
    return lines


def run_all(tests, args, bindir, expected):
    """Run tests in worker processes, args.jobs at a time, the longest
    expected first, the serial ones alone at the end; yields (name, outcome,
    reason, seconds, CPU seconds or None, system CPU seconds or None) as
    each ends."""
    parallel = sorted((t[0] for t in tests if not t[2]), key=lambda n: -expected.get(n, UNKNOWN_S))
    serial = [t[0] for t in tests if t[2]]
    running = {}  # pid -> [name, start, its pipe, output so far]
    sel = selectors.DefaultSelector()
    fn_of = {t[0]: t[1] for t in tests}

    def start(name):
        sys.stdout.flush()  # nothing buffered goes twice
        sys.stderr.flush()
        r, w = os.pipe()
        # No signal between the fork and the child's own handlers: the
        # runner's would have the child kill its siblings.
        signal.pthread_sigmask(signal.SIG_BLOCK, STOPS)
        pid = os.fork()
        if pid == 0:
            os.close(r)
            run_forked(name, fn_of[name], bindir, args.time_limit, args.keep, w)
        os.close(w)
        pipe = os.fdopen(r, "rb", buffering=0)
        os.set_blocking(r, False)
        running[pid] = [name, time.monotonic(), pipe, b""]
        sel.register(pipe, selectors.EVENT_READ, pid)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPS)  # the worker is in running: an interrupt reaches it

    def finish(pid):
        name, t0, pipe, raw = running.pop(pid)
        sel.unregister(pipe)
        pipe.close()
        _, status = os.waitpid(pid, 0)
        out = raw.decode(errors="replace")
        try:
            r = json.loads(out.strip().splitlines()[-1])
            return name, r["outcome"], r["reason"], r["took"], r.get("cpu"), r.get("sys")
        except (ValueError, IndexError, KeyError):
            return name, "fail", "its worker ended (%s) without a result: %s" % (
                os.waitstatus_to_exitcode(status), out[-500:]), time.monotonic() - t0, None, None

    try:
        for batch, width in ((parallel, max(1, args.jobs)), (serial, 1)):
            queue = list(batch)
            while queue or running:
                while queue and len(running) < width:
                    start(queue.pop(0))
                done = None
                while done is None:  # a worker is done when its output ends
                    for key, _ in sel.select():
                        pid = key.data
                        chunk = running[pid][2].read()
                        if chunk is None:  # nothing to read after all
                            continue
                        if chunk:
                            running[pid][3] += chunk
                        elif done is None:
                            done = pid
                yield finish(done)
    finally:
        # Interrupted: every worker is told to stop. Its handler has its
        # test's cleanup kill the programs the test started (each in a
        # session of its own); one that has not ended after that long is
        # killed.
        for pid in list(running):
            try:
                os.killpg(pid, signal.SIGTERM)
            except ProcessLookupError:  # not yet in a session of its own
                os.kill(pid, signal.SIGTERM)
        deadline = time.monotonic() + STOP_S
        for pid in list(running):
            while os.waitpid(pid, os.WNOHANG)[0] == 0:
                if time.monotonic() > deadline:
                    try:
                        os.killpg(pid, signal.SIGKILL)
                    except ProcessLookupError:
                        os.kill(pid, signal.SIGKILL)
                    os.waitpid(pid, 0)
                    break
                time.sleep(0.05)


def main():
    ap = argparse.ArgumentParser(description="Run the vmac integration tests.")
    ap.add_argument("--bin", required=True, help="folder with vmacd, vmac-board and vmac")
    ap.add_argument("--filter", action="append", default=[],
                    help="run only tests whose name contains this text (given again: any of them)")
    ap.add_argument("--plain-pass", action="store_true",
                    help="make test's plain pass: only the tests marked plain_pass_only or plain_pass_too "
                         "(the others run once, under the sanitizers)")
    ap.add_argument("--keep", action="store_true", help="keep the logs of passed tests too")
    ap.add_argument("--time-limit", type=float, default=300, help="seconds one test may take (default 300)")
    ap.add_argument("-j", "--jobs", type=int, default=int(os.environ.get("VMAC_TEST_JOBS", "4")),
                    help="tests run at a time (default 4, or $VMAC_TEST_JOBS)")
    args = ap.parse_args()

    bindir = os.path.abspath(args.bin)
    for program in ("vmacd", "vmac-board", "vmac"):
        if not os.access(os.path.join(bindir, program), os.X_OK):
            print("run.py: no executable %s in %s (build first: make all)" % (program, bindir), file=sys.stderr)
            return 2
    tests = collect(args.filter)
    if not tests:
        print("run.py: no test matches %r" % args.filter, file=sys.stderr)
        return 2
    # Which tests this pass runs: the sanitizer pass leaves those marked
    # harness.plain_pass_only to the plain pass, and make test's plain pass
    # (--plain-pass) runs only those and the ones marked plain_pass_too.
    sanitized = harness.sanitized(os.path.join(bindir, "vmacd"))
    if sanitized and args.plain_pass:
        print("run.py: --plain-pass is for the plain build, and %s is sanitized" % bindir, file=sys.stderr)
        return 2
    plain_only = [t for t in tests if getattr(t[1], "plain_pass_only", None)]
    if sanitized:
        tests = [t for t in tests if t not in plain_only]
        for name, fn, _ in plain_only:
            print("PLAIN %s: run by the plain pass only (%s)" % (name, fn.plain_pass_only), flush=True)
    elif args.plain_pass:
        kept = [t for t in tests if t in plain_only or getattr(t[1], "plain_pass_too", None)]
        print("ASAN %d tests: run by the sanitizer pass only (make test-asan)" % (len(tests) - len(kept)), flush=True)
        tests, plain_only = kept, []
    if not tests:
        print("run.py: no test of this pass matches %r" % args.filter, file=sys.stderr)
        return 2

    signal.signal(signal.SIGTERM, on_terminate)
    ci = os.environ.get("CI") == "true"
    skip_file = os.environ.get("VMAC_SKIP_FILE")
    passed = failed = 0
    skips = []
    started = time.monotonic()
    own_file = times_file(bindir)
    times = load_times(own_file)
    expected = expected_times(tests, times, load_times(PLAIN_TIMES_FILE) if own_file != PLAIN_TIMES_FILE else {})
    took_s, cpu_s, sys_s = {}, {}, {}  # every test that ran: seconds, and CPU seconds where its worker said
    for name, outcome, reason, took, cpu, sys_cpu in run_all(tests, args, bindir, expected):
        took_s[name] = took
        if cpu is not None:
            cpu_s[name], sys_s[name] = cpu, sys_cpu or 0.0
        if outcome == "skip" and ci:
            outcome, reason = "fail", "could not run, and CI=true makes that a failure: %s" % reason
        if outcome == "pass":
            passed += 1
            times[name] = round(took, 1)
            print("PASS %s (%.1f s)%s" % (name, took, reason), flush=True)
        elif outcome == "skip":
            skips.append((name, reason))
            print("#" * 80 + "\nSKIP %s (%.1f s): %s\n" % (name, took, reason) + "#" * 80, flush=True)
        else:
            failed += 1
            print("FAIL %s (%.1f s): %s" % (name, took, reason), flush=True)
    wall_s = time.monotonic() - started
    print("total %.0f s" % wall_s, file=sys.stderr, flush=True)
    save_times(own_file, times)
    if skips:
        print("SKIPPED (did not run, not passed):", flush=True)
        for name, reason in skips:
            print("  %s: %s" % (name, reason), flush=True)
        if skip_file:
            with open(skip_file, "a") as f:
                for name, reason in skips:
                    f.write("integration test %s (%s): %s\n" % (name, args.bin, reason))
    for line in longest_report(took_s, cpu_s, sys_s, wall_s, max(1, args.jobs)):
        print(line, flush=True)
    print("%d passed, %d failed, %d skipped%s" % (passed, failed, len(skips), ", %d left to the plain pass" % len(
        plain_only) if plain_only else ""), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt as e:  # every process of the running test is killed by now
        print("run.py: interrupted (%s)" % (e or "Ctrl-C"), file=sys.stderr)
        sys.exit(130)
