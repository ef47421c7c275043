#!/usr/bin/env python3
"""Integration test runner: runs every test_* function of
tests/integration/test_*.py against the real programs, each with fresh
processes on its own bus, and kills whatever a test started however it ends.

    python3 tests/integration/run.py --bin build/bin [--filter NAME]

Prints one PASS/FAIL line per test and ends with 'N passed, N failed'; the
exit code is 1 when any test failed. A failed test keeps its programs' output
in the log directory its FAIL line names."""

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
    """Run one test; returns (passed, reason)."""
    logdir = tempfile.mkdtemp(prefix="vmac-it-%s-" % name)
    ctx = harness.Context(bindir, logdir)
    failure = None
    signal.alarm(int(limit_s))
    try:
        fn(ctx)
    except Exception as e:  # every failure (TestTimeout too) is reported, none escapes
        failure = reason_of(e)
    finally:
        signal.alarm(0)
        report = ctx.cleanup()
    if report:
        failure = "%s%ssanitizer report from %s" % (failure or "", "; " if failure else "", report)
    if failure:
        return False, "%s [logs: %s]" % (failure, logdir)
    if keep:
        return True, " [logs: %s]" % logdir
    shutil.rmtree(logdir, ignore_errors=True)
    return True, ""


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
    passed = failed = 0
    started = time.monotonic()
    for name, fn in tests:
        t0 = time.monotonic()
        ok, reason = run_one(name, fn, bindir, args.time_limit, args.keep)
        took = time.monotonic() - t0
        if ok:
            passed += 1
            print("PASS %s (%.1f s)%s" % (name, took, reason), flush=True)
        else:
            failed += 1
            print("FAIL %s (%.1f s): %s" % (name, took, reason), flush=True)
    print("total %.0f s" % (time.monotonic() - started), file=sys.stderr, flush=True)
    print("%d passed, %d failed" % (passed, failed), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt as e:  # every process of the running test is killed by now
        print("run.py: interrupted (%s)" % (e or "Ctrl-C"), file=sys.stderr)
        sys.exit(130)
