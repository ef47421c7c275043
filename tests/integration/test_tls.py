"""TLS (docs/API.md "TLS"): with tls_cert and tls_key the API is served over
HTTPS only; vmac's commands reach it with https:// and the CA in
$VMAC_CACERT, and refuse a certificate they cannot verify; a half or broken
TLS configuration stops the host at start with a clear error."""

import json
import os
import ssl
import subprocess
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
