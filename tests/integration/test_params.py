"""Persisted parameters (docs/API.md "POST /api/devices/NAME/input",
docs/CLI.md "Console"): `>` sets a param and keeps it in the store; the value
comes back when the machine attaches again, after a restart of the host too;
only params declared persist = true persist, and a refused value stores
nothing."""

import os
import subprocess
import threading
import time

import harness


def params(host, name, status=None):
    return (host.device(name, status) or {}).get("params", {})


def running_params(host, name, timeout_s=30):
    """The params of machine name once it runs (its driver's attach has
    returned: test_a_running_machine_shows_what_its_attach_left)."""
    return params(host, name, host.wait_running([name], timeout_s=timeout_s))


# attach() takes a while: some 150 million instructions (half a second or
# more), with no allocation, which would cost far more under ASan.
SLOW_ATTACH = """local driver = { name = "slow_attach", version = "1", io = { lamp = "do0" },
	params = { level = { default = 3, min = 0, max = 9 } } }
function driver.attach(dev)
	local n = 0
	for i = 1, 30000000 do
		n = (n + i) % 1000003
	end
end
function driver.tick(dev, inputs) end
return driver
"""


def test_a_running_machine_shows_what_its_attach_left(t):
    """A machine is `running` in the status only once its driver's attach()
    has returned (docs/API.md, devices[].state): from then on its params
    are there, in every status. The status is polled as fast as the host
    answers, from before the board starts."""
    host = t.host(drivers=t.drivers(slow_attach=SLOW_ATTACH),
                  settings={"driver.slow_attach.budget_us": 10000000, "driver.slow_attach.instructions": 1000000000})
    seen = []  # (state, params) of slow-1 in each status

    def poll():
        deadline = time.monotonic() + 30 * harness.LOADED
        while time.monotonic() < deadline and len([x for x in seen if x[0] == "running"]) < 3:
            d = host.device("slow-1", host.get("/api/status")) or {}  # not status(): its event log is the test's
            seen.append((d.get("state"), d.get("params")))

    poller = threading.Thread(target=poll, daemon=True)
    poller.start()
    t.board("generic", "slow-1", driver="slow_attach")
    poller.join()
    running = [x for x in seen if x[0] == "running"]
    assert running, "slow-1 never ran; states seen: %s" % sorted({str(x[0]) for x in seen})
    assert "attaching" in [x[0] for x in seen], "slow-1 was never seen attaching: the test saw nothing of the attach"
    early = [x for x in running if x[1] != {"level": 3}]
    assert not early, "a status said running before the driver's attach had returned: %s" % early[:3]


def test_a_persisted_param_survives_a_restart(t):
    host = t.host()
    t.board("washer", "washer-1")
    p = running_params(host, "washer-1")
    assert p.get("program") == "normal", "the default programme: %r" % (p,)
    vmac = t.path("vmac")
    env = dict(os.environ, VMAC_HTTP=host.http, VMAC_TOKEN=t.make_token("operate"))

    def console(line):
        p = subprocess.run([vmac, "console"], input=line + "\n", capture_output=True, text=True, env=env, timeout=30)
        return p.returncode, p.stdout, p.stderr

    rc, out, err = console("washer-1.program>quick washer-1.time_scale>0.5 washer-1.program>nosuch "
                           "washer-1.state>idle washer-1.door_level_l:7")
    assert out == ("washer-1.program>quick washer-1.time_scale#6 washer-1.program#4 washer-1.state#6 "
                   "washer-1.door_level_l:7\n"), "console answers: %r (stderr %r)" % (out, err)
    assert "does not persist" in err and "not one of the allowed values" in err, \
        "the console does not say why: %r" % err
    # The status carries what each machine's last job left: both values,
    # set by two jobs, before they are read back.
    s = host.wait_status(lambda s: params(host, "washer-1", s).get("program") == "quick" and
                         params(host, "washer-1", s).get("door_level_l") == 7, 5,
                         "program quick and door_level_l 7 in the status")
    rc, out, err = console("washer-1.program? washer-1.door_level_l?")
    assert out == "washer-1.program:quick washer-1.door_level_l:7\n", "reading params back: %r %r" % (out, err)

    # The host stops and starts again on the same store: the persisted
    # programme is back, the value set without persistence is not.
    host.kill()
    host = t.host()
    p = running_params(host, "washer-1", timeout_s=60)
    assert p.get("program") == "quick", "the persisted programme was not restored: %r" % p
    assert p.get("door_level_l") == 5 and p.get("time_scale") == 1, \
        "values set without persistence came back: %r" % p
