#!/usr/bin/env python3
"""Integration test runner: runs every test_* function of
tests/integration/test_*.py against the real programs, each with fresh
processes on its own bus, and kills whatever a test started however it ends.

    python3 tests/integration/run.py --bin build/bin [--filter NAME]

Prints one PASS/FAIL/SKIP line per test and ends with 'N passed, N failed,
N skipped'; the exit code is 1 when any test failed. A failed test keeps its
programs' output in the log directory its FAIL line names.

A test that cannot run on this machine raises harness.Skip(reason) (e.g. one
that needs root for a mount namespace). It is printed as SKIP with a banner,
listed again at the end, and appended to the file $VMAC_SKIP_FILE when that
is set (make test prints every skipped suite at its end). With CI=true in the
environment a skip is a failure: a CI run must not pass what it did not run."""

import argparse
import glob
import importlib.util
import os
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


def on_terminate(signum, frame):
    raise KeyboardInterrupt("runner got signal %d" % signum)


def collect(name_filter):
    """(name, function) of every test, in file order then definition order."""
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
        tests += [(name, fn) for _, name, fn in sorted(found)]
    return [(n, f) for n, f in tests if not name_filter or name_filter in n]


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
    shutil.rmtree(logdir, ignore_errors=True)
    if skipped:
        return "skip", skipped
    if keep:
        return "pass", " [logs: %s]" % logdir
    return "pass", ""


def main():
    ap = argparse.ArgumentParser(description="Run the vmac integration tests.")
    ap.add_argument("--bin", required=True, help="folder with vmacd, vmac-board and vmac")
    ap.add_argument("--filter", default="", help="run only tests whose name contains this text")
    ap.add_argument("--keep", action="store_true", help="keep the logs of passed tests too")
    ap.add_argument("--time-limit", type=float, default=300, help="seconds one test may take (default 300)")
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

    signal.signal(signal.SIGALRM, on_alarm)
    signal.signal(signal.SIGTERM, on_terminate)
    ci = os.environ.get("CI") == "true"
    skip_file = os.environ.get("VMAC_SKIP_FILE")
    passed = failed = 0
    skips = []
    started = time.monotonic()
    for name, fn in tests:
        t0 = time.monotonic()
        outcome, reason = run_one(name, fn, bindir, args.time_limit, args.keep)
        took = time.monotonic() - t0
        if outcome == "skip" and ci:
            outcome, reason = "fail", "could not run, and CI=true makes that a failure: %s" % reason
        if outcome == "pass":
            passed += 1
            print("PASS %s (%.1f s)%s" % (name, took, reason), flush=True)
        elif outcome == "skip":
            skips.append((name, reason))
            print("#" * 80 + "\nSKIP %s (%.1f s): %s\n" % (name, took, reason) + "#" * 80, flush=True)
        else:
            failed += 1
            print("FAIL %s (%.1f s): %s" % (name, took, reason), flush=True)
    print("total %.0f s" % (time.monotonic() - started), file=sys.stderr, flush=True)
    if skips:
        print("SKIPPED (did not run, not passed):", flush=True)
        for name, reason in skips:
            print("  %s: %s" % (name, reason), flush=True)
        if skip_file:
            with open(skip_file, "a") as f:
                for name, reason in skips:
                    f.write("integration test %s (%s): %s\n" % (name, args.bin, reason))
    print("%d passed, %d failed, %d skipped" % (passed, failed, len(skips)), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt as e:  # every process of the running test is killed by now
        print("run.py: interrupted (%s)" % (e or "Ctrl-C"), file=sys.stderr)
        sys.exit(130)
