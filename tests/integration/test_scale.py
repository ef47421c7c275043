"""Many boards at once: one vmac-board process running --count boards, each
its own device on the host."""


from harness import undisturbed

COUNT = 20

# A driver of the user's own in --drivers, which takes precedence over the
# shipped scripts/drivers/generic.lua: it echoes the inputs to the outputs.
GENERIC_LUA = """-- generic stand-in: echo digital inputs 0..6 to the outputs
local driver = { name = "generic", version = "echo-1", io = {} }
for i = 0, 6 do
	driver.io["in" .. i] = "di" .. i
	driver.io["out" .. i] = "do" .. i
end
function driver.tick(dev, inputs)
	for i = 0, 6 do dev.out["out" .. i] = inputs["in" .. i] end
end
return driver
"""


def test_board_count(t):
    host = t.host(drivers=t.drivers(generic=GENERIC_LUA))
    t.board("generic", "g", count=COUNT)
    names = ["g-%d" % i for i in range(1, COUNT + 1)]
    status = host.wait_running(names, timeout_s=60)
    seen = sorted(d["name"] for d in status["devices"])
    assert seen == sorted(names), "devices %s, expected g-1..g-%d" % (seen, COUNT)
    # One vmac-board process serves its boards from one socket (one address);
    # the host tells them apart by their sessions and offsets.
    assert len({d["id"] for d in status["devices"]}) == COUNT, "two boards share a session id"
    assert len({d["offset"] for d in status["devices"]}) == COUNT, "two boards share an offset"
    assert len({d["id"] for d in status["devices"]}) == COUNT, "devices share an id"
    for d in status["devices"]:
        assert d["driver"] == "generic", "%s runs driver %r" % (d["name"], d["driver"])
    served = {d["name"]: d["served"] for d in status["devices"]}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 5 for n in names), 60,
                     "every one of the %d boards served" % COUNT, undisturbed(names))
