"""Access to the host's HTTP API (docs/API.md, "Access"): every request but
the health check needs a token of the store; tokens are made, listed and
revoked with vmac token, host running or not; failed attempts are limited
per client address."""

import http.client
import json
import os
import re
import socket
import subprocess
import time
import urllib.error
import urllib.request

EXIT_S = 30


def http_code(host, path, token=None, header=None):
    """(status code, parsed JSON body) of GET path, with a bearer token or a
    raw Authorization header."""
    req = urllib.request.Request("http://%s%s" % (host.http, path))
    if token is not None:
        req.add_header("Authorization", "Bearer " + token)
    if header is not None:
        req.add_header("Authorization", header)
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"{}")


def token_cmd(t, *args):
    p = subprocess.run([t.path("vmac"), "token"] + list(args) + ["--state", t.logdir], capture_output=True, text=True,
                       timeout=EXIT_S)
    return p.returncode, p.stdout, p.stderr


def test_requests_need_a_token_of_the_store(t):
    host = t.host()
    code, body = http_code(host, "/api/health")
    assert code == 200 and body.get("ok") is True, "the health check without a token: %d %r" % (code, body)

    code, body = http_code(host, "/api/status")
    assert code == 401 and "token" in body.get("error", ""), "status without a token: %d %r" % (code, body)
    for bad in ("nonsense", t.token[:-1] + ("0" if t.token[-1] != "0" else "1"), t.token + "0", ""):
        code, body = http_code(host, "/api/status", token=bad)
        assert code == 401, "status with a bad token %r: HTTP %d, expected 401" % (bad[:12], code)
    code, _ = http_code(host, "/api/status", header="Basic " + t.token)
    assert code == 401, "a token sent as Basic authentication was accepted (HTTP %d)" % code

    read = t.make_token("read")
    code, body = http_code(host, "/api/status", token=read)
    assert code == 200 and "devices" in body, "status with a read token: %d %r" % (code, body)


def test_vmac_status_takes_the_token_three_ways(t):
    host = t.host()
    vmac = t.path("vmac")
    env = {k: v for k, v in os.environ.items() if not k.startswith("VMAC_TOKEN")}
    p = subprocess.run([vmac, "status", "--http", host.http], capture_output=True, text=True, env=env,
                       timeout=EXIT_S)
    assert p.returncode == 1 and "401" in p.stderr and "--token" in p.stderr, (
        "vmac status without a token: exit %d, %r" % (p.returncode, p.stderr))
    p = subprocess.run([vmac, "status", "--http", host.http, "--token", t.token], capture_output=True, text=True,
                       env=env, timeout=EXIT_S)
    assert p.returncode == 0 and p.stdout.startswith("vmacd "), "vmac status --token: exit %d, %r" % (
        p.returncode, p.stderr)
    path = os.path.join(t.logdir, "token.txt")
    with open(path, "w") as f:
        f.write(t.token + "\n")
    p = subprocess.run([vmac, "status", "--http", host.http], capture_output=True, text=True,
                       env=dict(env, VMAC_TOKEN_FILE=path), timeout=EXIT_S)
    assert p.returncode == 0, "vmac status with $VMAC_TOKEN_FILE: exit %d, %r" % (p.returncode, p.stderr)
    p = subprocess.run([vmac, "status", "--http", host.http, "--token-file", "/nonexistent/token"],
                       capture_output=True, text=True, env=env, timeout=EXIT_S)
    assert p.returncode == 2 and "/nonexistent/token" in p.stderr, "a missing --token-file: exit %d, %r" % (
        p.returncode, p.stderr)


def test_tokens_are_listed_without_secrets_and_revoked_at_once(t):
    host = t.host()
    rc, token, err = token_cmd(t, "create", "--scope", "read", "--note", "wall panel")
    token = token.strip()
    assert rc == 0 and re.fullmatch(r"vmac_[0-9a-f]{16}_[0-9a-f]{64}", token), "create: exit %d, %r %r" % (
        rc, token, err)
    token_id = token.split("_")[1]
    assert http_code(host, "/api/status", token=token)[0] == 200, "the new token is refused"

    rc, out, err = token_cmd(t, "list")
    assert rc == 0, "list: exit %d, %s" % (rc, err)
    line = next((l for l in out.splitlines() if l.startswith(token_id)), None)
    assert line and "read" in line and "wall panel" in line, "list does not show the token:\n%s" % out
    assert token.split("_")[2] not in out, "list prints a secret"

    rc, out, err = token_cmd(t, "revoke", token_id)
    assert rc == 0, "revoke: exit %d, %s" % (rc, err)
    code, _ = http_code(host, "/api/status", token=token)
    assert code == 401, "a revoked token still works on the running host (HTTP %d)" % code
    assert http_code(host, "/api/status")[0] == 401
    assert http_code(host, "/api/status", token=t.token)[0] == 200, "revoking one token stopped another"
    rc, out, err = token_cmd(t, "revoke", token_id)
    assert rc == 1 and "no valid token" in err, "revoking twice: exit %d, %r" % (rc, err)

    for args, mention in ((["create", "--scope", "admin"], "--scope"), (["create"], "--scope"),
                          (["revoke"], "token ID"), (["frobnicate"], "unknown action")):
        rc, out, err = token_cmd(t, *args)
        assert rc == 2 and mention in err, "vmac token %s: exit %d, %r" % (" ".join(args), rc, err)


def wrong(token_id, n=0):
    """A token of the right shape with token_id and a wrong secret."""
    return "vmac_%s_%064x" % (token_id, n)


def test_guessing_is_locked_out_but_never_the_operator(t):
    """docs/API.md "Abuse": failures count per token id (a token of the
    right shape) or per address (anything else); ten in a minute lock that
    key out, and a valid token always gets in."""
    host = t.host()
    mine = t.token.split("_")[1]

    codes = [http_code(host, "/api/status", token=wrong("%016x" % 7, i))[0] for i in range(10)]
    assert codes == [401] * 10, "the first ten wrong secrets for one token id: %s" % codes
    code, body = http_code(host, "/api/status", token=wrong("%016x" % 7, 99))
    assert code == 429 and "token %016x" % 7 in body.get("error", ""), (
        "the eleventh wrong secret for that id within a minute: %d %r" % (code, body))

    codes = [http_code(host, "/api/status", header="Bearer junk-%d" % i)[0] for i in range(10)]
    assert codes == [401] * 10, "the first ten malformed tokens: %s" % codes
    code, body = http_code(host, "/api/status", header="Bearer junk")
    assert code == 429 and "address 127.0.0.1" in body.get("error", ""), (
        "the eleventh malformed token from this address: %d %r" % (code, body))

    # The operator's own token id attacked: its guesses are refused, the token is not.
    for i in range(11):
        http_code(host, "/api/status", token=wrong(mine, i))
    assert http_code(host, "/api/status", token=wrong(mine, 11))[0] == 429, "guesses at the operator's id go on"
    assert http_code(host, "/api/status", token=t.token)[0] == 200, (
        "the operator's valid token was locked out by someone guessing at it from the same address")
    assert http_code(host, "/api/health")[0] == 200, "the health check is locked out too"
    # Each lock-out is in the audit trail, with the request that caused it (docs/API.md "Audit trail").
    for key in ("token %s" % mine, "address 127.0.0.1"):
        locked = host.wait_event("audit", text="failed attempts with %s in 60 s: locked out (429)" % key)
        assert locked["text"].startswith("lockout by "), "a lock-out of another type: %r" % locked["text"]

    # 1,100 more guessers cannot push a locked key out of the table (1,024 entries).
    for i in range(1100):
        http_code(host, "/api/status", token=wrong("%016x" % (1000 + i)))
    code, _ = http_code(host, "/api/status", token=wrong("%016x" % 7, 100))
    assert code == 429, "a locked token id got a fresh count after 1,100 other guessers: HTTP %d" % code
    assert http_code(host, "/api/status", token=t.token)[0] == 200, "the operator's token after the crowd"


def test_slow_clients_cannot_take_the_api_away(t):
    """Slowloris: 300 connections from another address each dribbling a
    header line. One address holds at most http_connections_per_address;
    each is cut off when its headers are not in within
    http_header_timeout_s; the operator's requests go through all along."""
    host = t.host(settings={"http_header_timeout_s": 3})
    port = int(host.http.rsplit(":", 1)[1])
    slow = []
    try:
        for _ in range(300):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind(("127.0.0.2", 0))
            s.settimeout(2)
            try:
                s.connect(("127.0.0.1", port))
                s.sendall(b"GET /api/status HTTP/1.1\r\nHost: x\r\n")
            except OSError:
                s.close()
                continue
            slow.append(s)
        started = time.monotonic()
        while time.monotonic() - started < 8:  # past the header deadline, the attack going on
            for s in slow:
                try:
                    s.sendall(b"X-Slow: 1\r\n")
                except OSError:
                    pass
            code, _ = http_code(host, "/api/status", token=t.token)
            assert code == 200, "the operator's request during the attack: HTTP %d" % code
            time.sleep(0.5)  # the attacker's pace, not a synchronisation
    finally:
        for s in slow:
            s.close()
    cut = host.wait_event("http", text="connections cut off", timeout_s=20)
    n = int(cut["text"].split()[0])
    assert 0 < n <= 64 + 1, "%s (at most 64 from one address are let in)" % cut["text"]
    assert "127.0.0.2" in cut["text"], "the event does not say where from: %r" % cut["text"]


def test_a_kept_alive_client_waits_unharmed_but_a_slow_next_request_is_cut(t):
    """A client that keeps its connection between requests (a browser,
    Prometheus between scrapes) or opens one ahead of its request (a
    browser's preconnect) is idle, not slow: it is neither cut off nor
    reported at http_header_timeout_s, and its next request on the same
    connection is answered. The next request's headers are timed from its
    first line: trickled on a kept-alive connection, they are cut off and
    said, as on a new one (docs/API.md, "Abuse")."""
    host = t.host(settings={"http_header_timeout_s": 1})
    addr, port = host.http.rsplit(":", 1)
    ahead = socket.create_connection((addr, int(port)), timeout=10)  # nothing sent until after the wait below
    t.cleanups.append(ahead.close)
    kept = http.client.HTTPConnection(addr, int(port), timeout=10)
    t.cleanups.append(kept.close)
    for i in range(2):
        kept.request("GET", "/api/health")
        answer = kept.getresponse()
        answer.read()
        assert answer.status == 200, "request %d on the kept-alive connection: HTTP %d" % (i + 1, answer.status)
        if i == 0:
            time.sleep(2.5)  # idle for more than twice the header timeout: what is under test
    ahead.sendall(b"GET /api/health HTTP/1.1\r\nHost: x\r\n\r\n")
    assert ahead.recv(4096).startswith(b"HTTP/1.1 200"), "a connection opened ahead of its request was not answered"
    host.status()  # the events so far
    cut = [e for e in host.events.values() if "cut off" in e["text"]]
    assert not cut, "an idle connection (kept alive, or opened ahead) was reported: %r" % cut

    # Two kept-alive connections slow with their next request: one sends
    # its first line and no header, one only part of its first line.
    for start in (b"GET /api/health HTTP/1.1\r\n", b"GET /api/hea"):
        slow = socket.create_connection((addr, int(port)), timeout=5)
        t.cleanups.append(slow.close)
        slow.sendall(b"GET /api/health HTTP/1.1\r\nHost: x\r\n\r\n")
        assert slow.recv(4096).startswith(b"HTTP/1.1 200"), "the first request on a slow connection was not answered"
        slow.sendall(start)

    def cut_off(s):
        return sum(int(e["text"].split()[0]) for e in host.find_events("http", text="connections cut off"))

    host.wait_status(lambda s: cut_off(s) >= 2, 30, "both slow connections cut off and said")
    assert cut_off(host.status()) == 2, "more cut off than the two slow connections: %r" % [
        e["text"] for e in host.find_events("http", text="connections cut off")]


def test_a_state_folder_that_cannot_be_made_stops_the_host(t):
    p = subprocess.run([t.path("vmacd"), "--bus", t.bus, "--http", "127.0.0.1:0", "--state", "/nonexistent/state",
                        "--set", "realtime=false"], capture_output=True, text=True, timeout=EXIT_S)
    assert p.returncode == 1 and "/nonexistent/state" in p.stderr, (
        "vmacd with a state folder it cannot create: exit %d, %r" % (p.returncode, p.stderr))
