"""TLS (docs/API.md "TLS"): with tls_cert and tls_key the API is served over
HTTPS only; vmac's commands reach it with https:// and the CA in
$VMAC_CACERT, and refuse a certificate they cannot verify; a half or broken
TLS configuration stops the host at start with a clear error."""

import http.client
import json
import os
import socket
import ssl
import subprocess
import time
import urllib.request


def make_cert(t):
    """A self-signed certificate for 127.0.0.1: (cert path, key path)."""
    cert, key = os.path.join(t.logdir, "cert.pem"), os.path.join(t.logdir, "key.pem")
    p = subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", key, "-out", cert,
                        "-days", "2", "-subj", "/CN=127.0.0.1", "-addext", "subjectAltName=IP:127.0.0.1"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, "openssl could not make a test certificate: %s" % p.stderr
    return cert, key


def test_the_api_over_https(t):
    cert, key = make_cert(t)
    host = t.host(settings={"tls_cert": cert, "tls_key": key})
    assert host.scheme == "https", "the host says it serves %s" % host.scheme
    url = "https://%s" % host.http

    ctx = ssl.create_default_context(cafile=cert)
    req = urllib.request.Request(url + "/api/status", headers={"Authorization": "Bearer " + t.token})
    with urllib.request.urlopen(req, timeout=10, context=ctx) as r:
        assert r.status == 200 and "devices" in json.loads(r.read()), "GET /api/status over HTTPS"

    env = dict(os.environ, VMAC_TOKEN=t.token, VMAC_CACERT=cert)
    p = subprocess.run([t.path("vmac"), "status", "--http", url], capture_output=True, text=True, env=env,
                       timeout=30)
    assert p.returncode == 0 and "vmacd" in p.stdout, "vmac status over HTTPS: exit %d %r" % (p.returncode,
                                                                                         p.stderr)
    env.pop("VMAC_CACERT")
    p = subprocess.run([t.path("vmac"), "status", "--http", url], capture_output=True, text=True, env=env,
                       timeout=30)
    assert p.returncode == 1 and "certificate" in p.stderr.lower(), \
        "vmac status trusted a certificate it cannot verify: exit %d %r" % (p.returncode, p.stderr)
    p = subprocess.run([t.path("vmac"), "status", "--http", host.http], capture_output=True, text=True, env=env,
                       timeout=30)
    assert p.returncode == 1, "plain HTTP to the HTTPS port got an answer: %r" % p.stdout


def test_a_broken_tls_configuration_stops_the_host(t):
    cert, key = make_cert(t)
    vmacd = t.path("vmacd")
    cases = [
        (["--set", "tls_cert=" + cert], "TLS needs both"),
        (["--set", "tls_cert=" + cert, "--set", "tls_key=" + os.path.join(t.logdir, "missing.pem")], "missing.pem"),
        (["--set", "tls_cert=" + cert, "--set", "tls_key=" + os.path.join(os.path.dirname(__file__), "harness.py")],
         "not a PEM file"),
    ]
    for extra, want in cases:
        rc, out, err = t.run([vmacd, "--http", "127.0.0.1:0", "--state", t.logdir, "--set", "realtime=false"] + extra,
                             "vmacd-tls")
        assert rc != 0 and want in err, "vmacd %s: exit %s, stderr %r (wanted %r)" % (" ".join(extra), rc, err, want)


def test_a_browsers_tls_connections_are_idle_not_slow(t):
    """A browser opens an HTTPS connection ahead of its request (TCP and
    the TLS handshake, no request yet), and keeps one between requests:
    neither is cut off or reported at http_header_timeout_s, and each is
    answered when its request comes. A request's headers are still timed
    from their first byte: trickled over TLS, they are cut off and said
    (docs/API.md, "Abuse")."""
    cert, key = make_cert(t)
    host = t.host(settings={"tls_cert": cert, "tls_key": key, "http_header_timeout_s": 1})
    addr, port = host.http.rsplit(":", 1)
    ctx = ssl.create_default_context(cafile=cert)

    def connect():
        s = ctx.wrap_socket(socket.create_connection((addr, int(port)), timeout=10), server_hostname=addr)
        t.cleanups.append(s.close)
        return s

    def health(s):
        """GET /api/health on s: its status, the whole answer read."""
        s.sendall(b"GET /api/health HTTP/1.1\r\nHost: x\r\n\r\n")
        answer = http.client.HTTPResponse(s)
        answer.begin()
        answer.read()
        return answer.status

    ahead, kept = connect(), connect()  # the handshake done, nothing asked yet
    assert health(kept) == 200, "the first request on the kept-alive connection"
    time.sleep(2.5)  # idle for more than twice the header timeout: what is under test
    for name, s in (("opened ahead", ahead), ("kept alive", kept)):
        try:
            code = health(s)
        except (OSError, http.client.HTTPException) as e:
            code = repr(e)
        assert code == 200, "the HTTPS connection %s, after 2.5 s idle: %r" % (name, code)

    # A slowloris over TLS: a header line now and then, never the end.
    slow = connect()
    slow.sendall(b"GET /api/health HTTP/1.1\r\n")
    started = time.monotonic()
    while time.monotonic() - started < 30 and not any("connections cut off" in line.text
                                                      for line in host.lines["stderr"]):
        try:
            slow.sendall(b"X-Slow: 1\r\n")
        except OSError:
            pass  # cut off: the line says so
        time.sleep(0.5)  # the attacker's pace, not a synchronisation
    cut = host.wait_line(r"connections cut off", 10, stream="stderr", what="the slow HTTPS request cut off")
    assert "] 1 connections cut off" in cut.text, "more cut off than the one slow request: %r" % cut.text
