-- Tests of stdlib/cycle.lua: steps in order in virtual time, pause and hold,
-- resume, cancel with cleanup, wait_until timeouts, failure by step.

local T = require "testing"
local cycle = require "cycle"
local test = T.test

local DT = 0.1

-- A virtual bus: run(c, seconds) ticks c every DT seconds of bus time,
-- calling each(t) before each tick, and returns the last state.
local function new_bus()
	local bus = { t = 0, inp = {}, out = {} }
	function bus.run(c, seconds, each)
		local state
		for _ = 1, math.floor(seconds / DT + 0.5) do
			bus.t = bus.t + DT
			if each then each(bus.t) end
			state = c:tick(bus.t, bus.inp, bus.out)
		end
		return state
	end
	-- Tick until c is finished or max_s passed; returns the bus time.
	function bus.finish(c, max_s, each)
		local limit = bus.t + max_s
		while not c:finished() and bus.t < limit do bus.run(c, DT, each) end
		return bus.t
	end
	return bus
end

test("runs a step list in order, each wait in virtual time, then done", function()
	local log = {}
	local c = cycle.new({
		{ "fill", function(c)
			log[#log + 1] = { "fill", c:elapsed() }
			c.out.valve = true
			c:wait(10)
			c.out.valve = false
		end },
		{ "wash", function(c)
			log[#log + 1] = { "wash", c:elapsed() }
			c.out.motor_rpm = 45
			c:wait(20)
		end },
		{ "drain", function(c)
			log[#log + 1] = { "drain", c:elapsed() }
			c.out.motor_rpm = 0
			c:wait(5)
		end },
	})
	T.equal(c.state, "idle", "state before start")
	T.equal(#c.steps, 3, "steps declared by the list")
	T.equal(c.steps[2], "wash", "second step name")
	local bus = new_bus()
	T.equal(bus.run(c, 1), "idle", "state when ticked without start")
	T.equal(c:start(), true, "start()")
	bus.run(c, DT)
	T.equal(c.state, "running", "state after the first tick")
	T.equal(c.step_name, "fill", "step after the first tick")
	T.equal(bus.out.valve, true, "valve output during fill")
	bus.run(c, 12)
	T.equal(c.step_name, "wash", "step at 12 s")
	T.equal(c.step_index, 2, "step index at 12 s")
	T.near(c:wait_left(), 18, DT + 1e-9, "seconds left in the wash wait at 12 s")
	T.equal(bus.out.motor_rpm, 45, "motor output during wash")
	T.equal(bus.out.valve, false, "valve output during wash")
	local ended = bus.finish(c, 60)
	T.equal(c.state, "done", "state at the end")
	T.near(ended, 1 + DT + 35, 1e-9, "bus time at the end (35 s of steps from the tick at 1.1 s)")
	T.equal(#log, 3, "steps run")
	T.equal(log[1][1] .. " " .. log[2][1] .. " " .. log[3][1], "fill wash drain", "order of steps")
	T.near(log[2][2], 10, DT + 1e-9, "cycle time at which wash began")
	T.near(log[3][2], 30, DT + 1e-9, "cycle time at which drain began")
	T.equal(c:finished(), true, "finished() when done")
	local before = bus.out.motor_rpm
	bus.out.motor_rpm = 123
	bus.run(c, 1)
	T.equal(bus.out.motor_rpm, 123, "outputs untouched by ticks after the end (was %s)", tostring(before))
end)

test("a body function with c:step; declared names give step_index; restart after done", function()
	local order = {}
	local c = cycle.new(function(c)
		for round = 1, 2 do
			c:step("rinse", function()
				order[#order + 1] = "rinse" .. round .. "@" .. c.step_index
				c:wait(1)
			end)
			c:step("drain", function()
				order[#order + 1] = "drain" .. round .. "@" .. c.step_index
				c:wait(1)
			end)
		end
	end, { steps = { "rinse", "drain", "rinse", "drain" } })
	local bus = new_bus()
	c:start()
	bus.finish(c, 10)
	T.equal(table.concat(order, " "), "rinse1@1 drain1@2 rinse2@3 drain2@4", "steps and their indexes")
	T.equal(c.state, "done", "state at the end")
	T.equal(c:start(), true, "start() again after done")
	bus.finish(c, 10)
	T.equal(#order, 8, "steps run over two starts")
end)

test("pause holds: outputs safe, steps frozen, waits extended; resume continues", function()
	local c = cycle.new({
		{ "wash", function(c) c.out.motor_rpm = 45; c.out.lamp = true; c.out.mode = "wash"; c:wait(20) end },
		{ "rest", function(c) c.out.motor_rpm = 0; c:wait(1) end },
	})
	local bus = new_bus()
	c:start()
	bus.run(c, 5)
	T.equal(c:pause(), true, "pause()")
	bus.run(c, DT)
	T.equal(c.state, "paused", "state after pause")
	T.equal(bus.out.motor_rpm, 0, "number output while paused (default hold)")
	T.equal(bus.out.lamp, false, "boolean output while paused (default hold)")
	T.equal(bus.out.mode, "wash", "string output while paused (left alone)")
	local frozen = c:elapsed()
	bus.run(c, 30, function(t)
		T.equal(c.step_name, "wash", "step while paused at %.1f s", t)
		T.equal(bus.out.motor_rpm, 0, "motor output while paused at %.1f s", t)
	end)
	T.near(c:elapsed(), frozen, 1e-9, "cycle time after 30 s paused")
	T.equal(c:resume(), true, "resume()")
	bus.run(c, DT)
	T.equal(c.state, "running", "state after resume")
	T.equal(bus.out.motor_rpm, 45, "motor output restored after resume")
	local ended = bus.finish(c, 60)
	T.equal(c.state, "done", "state at the end")
	T.near(ended, 21 + 30, 3 * DT, "bus time at the end: 21 s of steps plus 30 s paused")
end)

test("a custom hold gets the outputs and the cycle every paused tick", function()
	local held = 0
	local c = cycle.new({ { "spin", function(c) c.out.motor_rpm = 400; c.out.lock = true; c:wait(60) end } }, {
		hold = function(out, c)
			held = held + 1
			out.motor_rpm = 0
			out.lock = c.inp.rpm > 5 -- keep the door locked while the drum turns
		end,
	})
	local bus = new_bus()
	bus.inp.rpm = 400
	c:start()
	bus.run(c, 1)
	c:pause("user")
	bus.run(c, 1)
	T.equal(held, 10, "hold calls in 1 s paused")
	T.equal(bus.out.lock, true, "lock held while the drum turns")
	bus.inp.rpm = 0
	bus.run(c, DT)
	T.equal(bus.out.lock, false, "lock released once the drum stopped")
end)

test("pause reasons stack: the cycle runs only when every reason is cleared", function()
	local c = cycle.new({ { "wait", function(c) c:wait(10) end } })
	local bus = new_bus()
	c:start()
	bus.run(c, 1)
	c:pause()
	c:pause("door open")
	T.equal(#c.pause_reasons, 2, "pause reasons")
	c:resume()
	bus.run(c, 1)
	T.equal(c.state, "paused", "state with one reason left")
	local ok, message = c:resume("user")
	T.equal(ok, nil, "resume() again returns nil")
	T.equal(message, "cycle is not paused by user", "resume() again message")
	c:resume("door open")
	bus.run(c, DT)
	T.equal(c.state, "running", "state with no reasons")
end)

test("cancel stops the steps and runs the cleanup to its end from safe outputs", function()
	local after_cancel = false
	local cleanup_saw
	local c = cycle.new({
		{ "fill", function(c) c.out.valve = true; c:wait(100); after_cancel = true end },
		{ "wash", function() after_cancel = true end },
	}, {
		cleanup = function(c)
			cleanup_saw = c.out.valve
			c:step("drain", function() c.out.pump = true; c:wait(5); c.out.pump = false end)
		end,
	})
	local bus = new_bus()
	c:start()
	bus.run(c, 3)
	T.equal(c:cancel(), true, "cancel()")
	T.equal(c.state, "cancelling", "state right after cancel()")
	bus.run(c, DT)
	T.equal(cleanup_saw, false, "valve as the cleanup began (made safe)")
	T.equal(bus.out.valve, false, "valve output during cleanup")
	T.equal(bus.out.pump, true, "pump output during cleanup")
	T.equal(c.step_name, "drain", "step name in the cleanup")
	T.equal(c:cancel(), nil, "cancel() while cancelling returns nil")
	bus.finish(c, 20)
	T.equal(c.state, "cancelled", "state after the cleanup")
	T.equal(bus.out.pump, false, "pump output at the end")
	T.equal(after_cancel, false, "the cancelled steps ran on")
	T.equal(c.error, nil, "error after a cancel")
end)

test("cancel without a cleanup: cancelled, outputs made safe on the next tick", function()
	local c = cycle.new({ { "wash", function(c) c.out.motor_rpm = 45; c:wait(100) end } })
	local bus = new_bus()
	c:start()
	bus.run(c, 1)
	c:cancel()
	T.equal(c.state, "cancelled", "state after cancel()")
	bus.run(c, DT)
	T.equal(bus.out.motor_rpm, 0, "motor output after the cancel")
	local ok, message = c:cancel()
	T.equal(ok, nil, "cancel() when finished returns nil")
	T.equal(message, "cycle is not running", "cancel() when finished: message")
end)

test("cancel from inside a step stops it there", function()
	local reached, cleaned = false, false
	local c = cycle.new({ { "check", function(c)
		c:cancel()
		reached = true
	end } }, { cleanup = function() cleaned = true end })
	local bus = new_bus()
	c:start()
	bus.finish(c, 5)
	T.equal(reached, false, "code after cancel() in the step ran")
	T.equal(c.state, "cancelled", "state")
	T.equal(cleaned, true, "cleanup ran")
end)

test("cancel while paused clears the user's pause and runs the cleanup", function()
	local c = cycle.new({ { "wash", function(c) c:wait(100) end } }, {
		cleanup = function(c) c:wait(2) end,
	})
	local bus = new_bus()
	c:start()
	bus.run(c, 1)
	c:pause()
	bus.run(c, 1)
	c:cancel()
	T.equal(c.state, "cancelling", "state after cancel() while paused")
	bus.finish(c, 5)
	T.equal(c.state, "cancelled", "state at the end")
end)

test("wait_until returns once the condition holds, checked every tick", function()
	local c = cycle.new({ { "fill", function(c)
		c.out.valve = true
		c:wait_until(function() return c.inp.level_l >= 10 end, 120, "level 10 l")
		c.out.valve = false
	end } })
	local bus = new_bus()
	bus.inp.level_l = 0
	c:start()
	bus.finish(c, 60, function() if bus.out.valve then bus.inp.level_l = bus.inp.level_l + 0.5 * DT end end)
	T.equal(c.state, "done", "state")
	T.near(bus.t, 20, 3 * DT, "bus time to fill 10 l at 0.5 l/s")
end)

test("wait_until times out: the cycle fails naming the step, after its cleanup", function()
	local c = cycle.new({
		{ "lock", function(c) c:wait(1) end },
		{ "fill", function(c)
			c.out.valve = true
			c:wait_until(function() return c.inp.level_l >= 10 end, 120, "level 10 l")
		end },
	}, { cleanup = function(c) c.out.pump = true; c:wait(3) end })
	local bus = new_bus()
	bus.inp.level_l = 0
	c:start()
	bus.run(c, 1 + 120 - DT)
	T.equal(c.state, "running", "state just before the timeout")
	bus.run(c, 2 * DT)
	T.equal(c.state, "cancelling", "state right after the timeout (cleanup running)")
	T.equal(c.error, "fill: timed out after 120 s waiting for level 10 l", "error")
	T.equal(c.error_step, "fill", "error_step")
	T.equal(bus.out.valve, false, "valve output in the cleanup")
	bus.finish(c, 10)
	T.equal(c.state, "failed", "state after the cleanup")
end)

test("try_wait_until returns false on timeout and the step goes on", function()
	local result
	local c = cycle.new({ { "fill", function(c)
		result = c:try_wait_until(function() return false end, 5)
	end } })
	local bus = new_bus()
	c:start()
	local ended = bus.finish(c, 20)
	T.equal(result, false, "try_wait_until result")
	T.equal(c.state, "done", "state")
	T.near(ended, 5, 2 * DT, "bus time when it gave up")
end)

test("an error in a step fails the cycle with the step name and message", function()
	local c = cycle.new({
		{ "fill", function(c) c:wait(1) end },
		{ "wash", function(c) c:wait(1); error("motor fault") end },
		{ "spin", function() end },
	})
	local bus = new_bus()
	c:start()
	bus.finish(c, 10)
	T.equal(c.state, "failed", "state")
	T.equal(c.error_step, "wash", "error_step")
	T.check(c.error:find("^wash: .*motor fault$"), "error names the step and message, got %q", c.error)
	T.check(c.error:find("test_cycle.lua", 1, true), "error carries the file and line, got %q", c.error)
end)

test("an error in the cleanup fails it and is added to the first error", function()
	local c = cycle.new({ { "wash", function() error("first", 0) end } }, {
		cleanup = function(c) c:step("drain", function() error("second", 0) end) end,
	})
	local bus = new_bus()
	c:start()
	bus.finish(c, 10)
	T.equal(c.state, "failed", "state")
	T.equal(c.error, "wash: first; then in cleanup, drain: second", "error")
end)

test("misuse raises clear errors", function()
	T.fails(function() cycle.new(42) end, "cycle.new: body must be a function", "cycle.new(42)")
	T.fails(function() cycle.new({ { "fill" } }) end, "cycle.new: step 1 must be {name, function(c) ... end}",
		"step without function")
	T.fails(function() cycle.new({}) end, "cycle.new: the step list is empty", "empty list")
	T.fails(function() cycle.new(function() end, { cleanup = 1 }) end, "cycle.new: cleanup must be a function",
		"cleanup = 1")
	T.fails(function() cycle.new(function() end, { interlocks = { {} } }) end,
		"cycle.new: interlocks[1] is not an interlock", "interlocks = {{}}")
	local c = cycle.new(function(c) c:wait(1) end)
	T.fails(function() c:wait(1) end, "cycle:wait: call it only from inside the cycle's steps", "wait outside")
	T.fails(function() c:tick(nil, {}, {}) end, "cycle:tick: now must be a number", "tick(nil)")
	T.fails(function() c:tick(1, {}) end, "cycle:tick: outputs must be a table", "tick without outputs")
	c:start()
	c:tick(5, {}, {})
	T.fails(function() c:tick(4, {}, {}) end, "cycle:tick: time went backwards (4 s after 5 s)", "time backwards")
	local ok, message = c:start()
	T.equal(ok, nil, "start() while running returns nil")
	T.equal(message, "cycle is already running", "start() while running: message")
	local nested = cycle.new(function(n) n:step("a", function() n:step("b", function() end) end) end)
	nested:start()
	nested:tick(0, {}, {})
	T.equal(nested.state, "failed", "state after nested steps")
	T.check(nested.error:find("steps do not nest", 1, true), "nested step error, got %q", nested.error)
	local waits = cycle.new(function(w) w:wait(-1) end)
	waits:start()
	waits:tick(0, {}, {})
	T.check(waits.error:find("cycle:wait: seconds must be a number >= 0", 1, true), "wait(-1) error, got %q",
		waits.error)
end)

test("an error outside any step is blamed on the cycle, or on the cleanup", function()
	local c = cycle.new(function(c)
		c:step("fill", function() c:wait(1) end)
		error("between steps", 0)
	end, { cleanup = function() error("in cleanup", 0) end })
	local bus = new_bus()
	c:start()
	bus.finish(c, 5)
	T.equal(c.error, "cycle: between steps; then in cleanup, cleanup: in cleanup", "error")
	T.equal(c.error_step, "cycle", "error_step")
end)
