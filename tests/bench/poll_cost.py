#!/usr/bin/env python3
"""What one look at GET /api/status costs, with a new connection each look
(urllib, as the integration harness did) and on one connection kept alive
(as the harness does now): the CPU of the client and of vmacd per look,
for the integration tests' own cost (docs/TESTING.md, "What make test
costs"). Not part of make bench: it measures the test suite, not vmac.

    python3 tests/bench/poll_cost.py --bin build/asan/bin [--looks 500] [--rounds 2]

Starts an idle vmacd (no boards) on a bus and state folder of its own,
makes a read token, and alternates the two ways round by round; the
host's CPU is its utime+stime from /proc/PID/stat."""

import argparse
import http.client
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request


def host_cpu_s(pid):
    fields = open("/proc/%d/stat" % pid).read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def looks(addr, token, pid, n, kept):
    conn = None
    headers = {"Authorization": "Bearer " + token}
    c0, h0 = time.process_time(), host_cpu_s(pid)
    for _ in range(n):
        if kept:
            if conn is None:
                host, port = addr.rsplit(":", 1)
                conn = http.client.HTTPConnection(host, int(port), timeout=10)
            conn.request("GET", "/api/status", headers=headers)
            json.loads(conn.getresponse().read())
        else:
            req = urllib.request.Request("http://%s/api/status" % addr, headers=headers)
            with urllib.request.urlopen(req, timeout=10) as r:
                json.loads(r.read())
    if conn:
        conn.close()
    return (time.process_time() - c0) * 1e3 / n, (host_cpu_s(pid) - h0) * 1e3 / n


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", required=True, help="folder with vmacd and vmac")
    ap.add_argument("--looks", type=int, default=500, help="looks per way per round (default 500)")
    ap.add_argument("--rounds", type=int, default=2, help="rounds, each both ways (default 2)")
    a = ap.parse_args()
    state = tempfile.mkdtemp(prefix="vmac-poll-")
    host = None
    try:
        made = subprocess.run([os.path.join(a.bin, "vmac"), "token", "create", "--state", state, "--scope", "read",
                               "--name", "poll"], capture_output=True, text=True, check=True)
        token = re.search(r"vmac_[0-9a-f]+_[0-9a-f]+", made.stdout + made.stderr).group(0)
        bus = "239.255.%d.%d:%d" % (random.randint(1, 254), random.randint(1, 254), random.randint(20000, 60000))
        host = subprocess.Popen([os.path.join(a.bin, "vmacd"), "--bus", bus, "--http", "127.0.0.1:0", "--state", state,
                                 "--set", "realtime=false"], stderr=subprocess.PIPE, text=True)
        for line in host.stderr:
            m = re.search(r"status at http://(\S+)/api/status", line)
            if m:
                break
        else:
            sys.exit("poll_cost: vmacd did not start")
        print("ms of CPU per look, %d looks a round (client, vmacd):" % a.looks)
        for r in range(a.rounds):
            for kept in (False, True):
                client, served = looks(m.group(1), token, host.pid, a.looks, kept)
                print("  round %d  %-22s client %.2f  vmacd %.2f" % (r + 1, "one kept alive" if kept
                                                                      else "a new connection each", client, served))
    finally:
        if host:
            host.terminate()
            host.wait(timeout=30)
        shutil.rmtree(state, ignore_errors=True)


if __name__ == "__main__":
    main()
