-- Time-triggered I/O in virtual time (docs/TESTING.md, "Board clocks"): the
-- two boards of one machine, their clocks 200 ppm and seconds apart, change
-- their outputs at one instant once their clocks lock, served by the cyclic
-- frame or by unicast UPDATEs; without clock sync
-- they act when their frames arrive. Run with --drivers tests/vtest/drivers
-- (tests/integration/test_vtest.py); each test prints its numbers.

local function press(minor, clock)
	return board { name = "press-" .. minor, plant = "generic", driver = "press", major = 7, minor = minor,
		clock = clock }
end

-- Both boards' outputs within 10 us of each other at every instant both
-- acted at, once both act at host instants.
local function one_instant(cyclic)
	config { clock_sync_ms = 1, cyclic = cyclic }
	local a = press(0, { ppm = 100, offset = 2.5, jitter = 20e-6, wander = 0.02 })
	local b = press(1, { ppm = -100, offset = -3.25, jitter = 20e-6, wander = 0.02 })
	local function timed(x) return x.clock.output and x.clock.output.how == "instant" end
	local took = run_until(function() return timed(a) and timed(b) end, 3, "both boards acting at host instants")
	print(string.format("timed after %.3f s", took))
	local worst, n = 0, 0
	local e = every(0.004, function()
		local oa, ob = a.clock.output, b.clock.output
		if oa.asked == ob.asked then
			expect(oa.how == "instant" and ob.how == "instant", "both boards acted at the instant, not " ..
				oa.how .. " and " .. ob.how)
			worst = math.max(worst, math.abs(oa.time - ob.time))
			expect(math.abs(oa.time - oa.asked) <= 60e-6, "press-0 acted within 60 us of its instant")
			n = n + 1
		end
	end)
	run_for(2)
	e:stop()
	print(string.format("timed spread: %d instants compared, worst %.3f us", n, worst * 1e6))
	expect(n >= 100, "at least 100 instants compared, got " .. n)
	expect(worst <= 10e-6, string.format("the boards' outputs within 10 us of each other, worst %.3f us", worst * 1e6))
end

test("two boards of one machine change their outputs at one instant", function()
	one_instant(true)
end)

-- Served by unicast (cyclic off): each board's UPDATE is a TIMED UPDATE
-- (docs/PROTOCOL.md, "The TIMED UPDATE"), acted at the same instants.
test("two boards of one machine served by unicast change their outputs at one instant", function()
	one_instant(false)
end)

test("without clock sync the boards act on arrival", function()
	local a = press(0, { ppm = 100, offset = 2.5, jitter = 20e-6 })
	local b = press(1, { ppm = -100, offset = -3.25, jitter = 20e-6 })
	run_until(function() return a.state == "running" and b.state == "running" end, 3, "the press running")
	run_for(1)
	expect(a.clock.output == nil and b.clock.output == nil, "no TIMED frame without clock sync")
	expect_eq(a.clock.state, "unsynced", "press-0's clock without SYNC")
end)

-- A tick asked for on the primary's reply waits while the tick before it
-- still runs; the other board's reply may come in the meantime. The tick
-- is given the inputs the host held at its time, never one sampled after
-- it (docs/DRIVERS.md, dev.t: at most a period before inputs.time).
test("a tick that waited for its worker has no inputs sampled after its time", function()
	config { ["driver.sampled.budget_us"] = 50000 }
	-- Past the 16 ms period: a tick asked for waits for the one before, and
	-- is handed over at a slot's start, after the other board's reply.
	driver_cost("sampled", 0.025)
	local a = board { name = "probe-0", plant = "generic", driver = "sampled", major = 8, minor = 0 }
	local b = board { name = "probe-1", plant = "generic", driver = "sampled", major = 8, minor = 1 }
	run_until(function() return a.state == "running" and b.state == "running" end, 3, "both boards running")
	run_for(1)
	local vars = a.device.vars.ticks and a.device.vars or b.device.vars
	print(string.format("waited ticks: %d, a board's inputs at most %.1f us after its tick's time",
		vars.ticks, vars.after_us))
	expect(vars.ticks >= 25, "at least 25 ticks in a second, got " .. tostring(vars.ticks))
	expect(vars.after_us <= 0, string.format("a board's inputs sampled %.1f us after its tick's time", vars.after_us))
end)
