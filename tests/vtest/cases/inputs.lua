-- Operator input and its answers in virtual time (docs/TESTING.md,
-- b:input and b:try_input), against tests/vtest/drivers/fragile.lua: an
-- input the driver takes, one it refuses, and one it fails in, which
-- drops the machine and is never reported as taken. Run with --drivers
-- tests/vtest/drivers (tests/integration/test_vtest.py).

test("an input the driver fails in is refused, and its machine dropped", function()
	local b = board { name = "fragile-1", plant = "generic", driver = "fragile" }
	run_until(function() return b.state == "running" end, 3, "fragile-1 running")
	b:input("set")
	run_until(function() return b.out.lamp end, 0.1, "the lamp on")
	local ok, reply = b:try_input("refuse")
	expect(not ok and tostring(reply):find("not now", 1, true), "a refused input: " .. tostring(reply))
	ok, reply = b:try_input("fail")
	expect(not ok, "an input the driver failed in was reported as taken: " .. tostring(reply))
	expect(tostring(reply):find("failing on purpose", 1, true), "the reply says why: " .. tostring(reply))
	expect_event { kind = "driver_error", device = "fragile-1", text = "failing on purpose" }
	run_until(function() return not b.out.lamp end, 1, "the lamp off: its board safe")
	expect(b.state ~= "running", "fragile-1 still running: " .. tostring(b.state))
end)
