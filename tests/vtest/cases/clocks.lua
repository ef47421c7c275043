-- Board clocks in virtual time (docs/TESTING.md, "Board clocks"): boards
-- whose counters drift and start seconds apart lock onto the host's SYNC,
-- hold over without it, track a step of drift; the same seed gives the same
-- numbers (each test prints them: tests/integration/test_vtest.py compares
-- two runs). The last two tests fail on purpose: mistakes in the clock API.

local function line(b, what)
	local c = b.clock
	print(string.format("clock %s %s: %s offset %.9f s bound %.3f us error %.3f us drift %.3f ppm (true %.3f) syncs %d",
		b.name, what, c.state, c.offset or 0 / 0, (c.bound or 0 / 0) * 1e6, (c.error or 0 / 0) * 1e6,
		c.drift_ppm or 0 / 0, c.true_ppm, c.syncs))
end

local function both_locked(a, b) return a.clock.state == "locked" and b.clock.state == "locked" end

local function lights(name, clock) return board { name = name, plant = "lights", driver = "lights", clock = clock } end

test("two boards at +-100 ppm, seconds apart, lock within 2 s", function()
	config { clock_sync_ms = 1 }
	local a = lights("lights-1", { ppm = 100, offset = 2.5, jitter = 20e-6, wander = 0.02 })
	local b = lights("lights-2", { ppm = -100, offset = -3.25, jitter = 20e-6, wander = 0.02 })
	expect_eq(a.clock.state, "unsynced", "a's clock before the first SYNC")
	local took = run_until(function() return both_locked(a, b) end, 2, "both clocks locked")
	print(string.format("clock locked after %.3f s", took))
	for _, x in ipairs { { a, 2.5 }, { b, -3.25 } } do
		local c = x[1].clock
		line(x[1], "at lock")
		expect_near(c.offset, x[2], 1e-3, x[1].name .. "'s offset, seconds")
		expect(c.bound <= 10e-6, x[1].name .. "'s bound within 10 us")
		expect(math.abs(c.error) <= c.bound, x[1].name .. "'s true error within its bound")
	end
	always("both clocks stay locked", function() return both_locked(a, b) end)
	run_for(3)
	for _, x in ipairs { a, b } do
		line(x, "after 3 s")
		expect_near(x.clock.drift_ppm, x.clock.true_ppm, 3, x.name .. "'s learnt drift, ppm")
		expect(math.abs(x.clock.error) <= 10e-6, x.name .. "'s error within 10 us")
	end
end)

test("without SYNC a board holds over within its bound, then is lost", function()
	config { clock_sync_ms = 1 }
	local a = lights("lights-1", { ppm = 150, offset = 1, jitter = 20e-6 })
	run_until(function() return a.clock.state == "locked" end, 2, "locked")
	run_for(2)
	a:unplug() -- SYNC no longer reaches it
	run_for(1)
	line(a, "1 s unplugged")
	expect_eq(a.clock.state, "holdover", "the clock 1 s without SYNC")
	expect(math.abs(a.clock.error) <= a.clock.bound, "the true error within the bound in holdover")
	local took = run_until(function() return a.clock.state == "lost" end, 60, "the clock lost")
	print(string.format("clock lights-1 lost %.3f s after holdover's first second", took))
	expect(a.clock.offset == nil and a.clock.bound == nil, "a lost clock has no offset or bound")
	a:replug()
	run_until(function() return a.clock.state == "locked" end, 2, "locked again")
	line(a, "replugged")
end)

test("a step of drift (temperature) is tracked", function()
	config { clock_sync_ms = 1 }
	local a = lights("lights-1", { ppm = -80, offset = 0.5, jitter = 20e-6 })
	run_until(function() return a.clock.state == "locked" end, 2, "locked")
	run_for(1)
	a:clock_step(50)
	run_for(0.5)
	expect_near(a.clock.true_ppm, -30, 1e-9, "the true drift after the step")
	run_for(2.5)
	line(a, "3 s after a step of +50 ppm")
	expect_eq(a.clock.state, "locked", "the clock after the step")
	expect_near(a.clock.drift_ppm, -30, 2, "the learnt drift after the step, ppm")
	expect(math.abs(a.clock.error) <= a.clock.bound, "the true error within the bound")
end)

test("a board without a clock of its own has a perfect one; SYNC is off unless asked", function()
	local quiet = lights("lights-1")
	run_for(1)
	expect_eq(quiet.clock.state, "unsynced", "a clock without SYNC (clock_sync_ms 0)")
	expect_eq(quiet.clock.syncs, 0, "SYNC samples without clock_sync_ms")
end)

test("a perfect clock locks onto SYNC", function()
	config { clock_sync_ms = 1 }
	local a = lights("lights-1")
	run_until(function() return a.clock.state == "locked" end, 2, "locked")
	expect_near(a.clock.offset, 50e-6, 1e-6, "the offset: the wire's 50 us, which a one-way clock cannot see")
	expect_near(a.clock.error, 0, 1e-6, "the error")
	expect_eq(a.clock.true_ppm, 0, "the true drift")
end)

test("a clock beyond 1000 ppm", function()
	lights("lights-1", { ppm = 5000 })
end)

test("a clock step out of range", function()
	local a = lights("lights-1", { ppm = 900 })
	a:clock_step(200)
end)
