-- Tests of cycle:restore (stdlib/cycle.lua): a cycle of one driver instance
-- continued by another after a hot reload. The old cycle runs here, its
-- dev.state is copied as the host copies it (host_copy: plain data, no
-- functions, coroutines or metatables, shared tables kept), and a new cycle
-- takes over on the same bus clock.

local T = require "testing"
local cycle = require "cycle"
local interlock = require "interlock"
local host_copy = require "host_copy"
local test = T.test

local DT = 0.1

-- The stdlib of the new driver instance. The test runs in one driver state
-- (tests/lua/run.c), where a module loads once, so these are the same
-- modules the old cycle was built from, not a second state's own copies.
local function new_instance()
	return { cycle = cycle, interlock = interlock }
end

-- The reload itself: the old dev.state as the new version's migrate gets it.
local function reload(old_cycle)
	return host_copy.state({ cycle = old_cycle }).cycle
end

local function new_bus()
	local bus = { t = 0, inp = {}, out = {} }
	function bus.run(c, seconds)
		for _ = 1, math.floor(seconds / DT + 0.5) do
			bus.t = bus.t + DT
			c:tick(bus.t, bus.inp, bus.out)
		end
		return c.state
	end
	function bus.finish(c, max_s)
		local limit = bus.t + max_s
		while not c:finished() and bus.t < limit do bus.run(c, DT) end
		return bus.t
	end
	return bus
end

local function counts()
	return { fill = 0, wash = 0, drain = 0, cleanup = 0 }
end

-- A small programme: fill 10 s, wash 240 s, drain 5 s; runs counts how
-- often the code of each step (and of the cleanup) began.
local function programme(cycle_module, runs, extra)
	local options = {
		outputs = { valve = false, motor_rpm = 0, pump = false },
		cleanup = function(c)
			runs.cleanup = runs.cleanup + 1
			c:step("pump out", function() c.out.pump = true; c:wait(5); c.out.pump = false end)
		end,
	}
	for k, v in pairs(extra or {}) do options[k] = v end
	return cycle_module.new({
		{ "fill", function(c) runs.fill = runs.fill + 1; c.out.valve = true; c:wait(10); c.out.valve = false end },
		{ "wash", function(c) runs.wash = runs.wash + 1; c.out.motor_rpm = 45; c:wait(240); c.out.motor_rpm = 0 end },
		{ "drain", function(c) runs.drain = runs.drain + 1; c.out.pump = true; c:wait(5); c.out.pump = false end },
	}, options)
end

-- An old cycle 60 s into its wash (70 s of bus time), on bus.
local function washing(bus, runs)
	local old = programme(cycle, runs)
	old:start()
	bus.run(old, 70)
	T.equal(old.step_name, "wash", "the old cycle's step at 70 s")
	return old
end

test("the test copy drops what the host drops and keeps shared tables", function()
	local shared = { 1, 2 }
	local object = setmetatable({ f = function() end, co = coroutine.create(function() end), n = 3 }, {})
	local state = { a = shared, b = shared, object = object, [function() end] = true }
	state.self = state
	local copy = host_copy.state(state)
	T.equal(copy.a, copy.b, "a table reached twice is one table")
	T.equal(copy.self, copy, "a cycle stays a cycle")
	T.equal(copy.object.f, nil, "a function value")
	T.equal(copy.object.co, nil, "a coroutine value")
	T.equal(copy.object.n, 3, "a number")
	T.equal(getmetatable(copy.object), nil, "the metatable")
	local keys = 0
	for _ in pairs(copy) do keys = keys + 1 end
	T.equal(keys, 4, "entries of the copy (a, b, object, self; the function key is gone)")
end)

test("a running cycle goes on in the same step with the time it had left; finished steps do not run again",
	function()
		local bus = new_bus()
		local old_runs, runs = counts(), counts()
		local old = washing(bus, old_runs)
		local left = old:wait_left()
		T.near(left, 180.1, 1e-6, "the old wash's time left")

		local c = programme(new_instance().cycle, runs)
		T.equal(c:restore(reload(old)), true, "restore()")
		T.equal(c.state, "running", "state before the first tick")
		T.equal(c.step_name, "wash", "step shown before the first tick")
		T.near(c:wait_left(), left, 1e-9, "time left shown before the first tick")
		T.near(c:elapsed(), old:elapsed(), 1e-9, "cycle time before the first tick")

		bus.run(c, DT)
		T.equal(runs.fill, 0, "times fill ran again")
		T.equal(runs.wash, 1, "times the wash began again")
		T.equal(c.step_name, "wash", "step after the first tick")
		T.equal(c.step_index, 2, "step index after the first tick")
		T.equal(bus.out.motor_rpm, 45, "motor output")
		T.equal(bus.out.valve, false, "valve output")
		T.near(c:wait_left(), left - DT, 1e-6, "time left after the first tick")
		T.near(c:elapsed(), 70, 1e-6, "the cycle clock went on from the old one")
		T.near(c:step_elapsed(), 60, 1e-6, "seconds in the wash, the old instance's included")

		local ended = bus.finish(c, 400)
		T.equal(c.state, "done", "state at the end")
		T.near(ended - 70, left + 5, 2 * DT, "seconds from the reload to the end (rest of the wash, drain)")
		T.equal(runs.wash, 1, "times the wash ran in the new instance")
		T.equal(runs.drain, 1, "times the drain ran in the new instance")
	end)

test("waits the old instance had finished in its step are not waited again", function()
	local function rinse(cycle_module)
		return cycle_module.new({
			{ "fill", function(c) c:wait(1) end },
			{ "rinse", function(c)
				for round = 1, 3 do
					c.out.round = round
					c:wait(10)
				end
			end },
		})
	end
	local bus = new_bus()
	local old = rinse(cycle)
	old:start()
	bus.run(old, 1 + 25)
	T.equal(old.out.round, 3, "the old instance's round")
	local left = old:wait_left()
	T.near(left, 5.1, 1e-6, "time left in the old instance's third round")
	local c = rinse(new_instance().cycle)
	c:restore(reload(old))
	bus.run(c, DT)
	T.equal(bus.out.round, 3, "round after the first tick: the first two waits counted as done")
	T.near(c:wait_left(), left - DT, 1e-6, "time left in the third round")
	bus.finish(c, 10)
	T.equal(c.state, "done", "state")
	T.near(bus.t, 26 + left, 2 * DT, "bus time at the end")
end)

test("code outside the steps runs again, and a skipped step returns nil", function()
	local function body(log)
		return function(c)
			log.body = log.body + 1
			log.measured = c:step("measure", function() c:wait(1); return 42 end)
			c:step("use", function() c:wait(10) end)
		end
	end
	local bus = new_bus()
	local old_log, log = { body = 0 }, { body = 0 }
	local old = cycle.new(body(old_log))
	old:start()
	bus.run(old, 5)
	T.equal(old_log.measured, 42, "what measure returned in the old instance")
	local c = new_instance().cycle.new(body(log))
	c:restore(reload(old))
	bus.run(c, DT)
	T.equal(log.body, 1, "times the body began in the new instance")
	T.equal(log.measured, nil, "what the skipped measure returned")
	T.equal(c.step_name, "use", "step")
end)

test("a user pause stays paused: nothing runs until resume, then the step goes on", function()
	local bus = new_bus()
	local runs = counts()
	local old = washing(bus, counts())
	old:pause()
	bus.run(old, DT)
	T.equal(old.state, "paused", "old state")
	local left = old:wait_left()

	local c = programme(new_instance().cycle, runs)
	c:restore(reload(old))
	T.equal(c.state, "paused", "state after restore")
	T.equal(c.pause_reasons[1], "user", "pause reason")
	bus.run(c, 30)
	T.equal(c.state, "paused", "state 30 s later")
	T.equal(runs.wash, 0, "times the wash ran while paused")
	T.equal(bus.out.motor_rpm, 0, "motor output while paused (hold)")
	T.near(c:wait_left(), left, 1e-9, "time left shown while paused")
	T.equal(c:resume(), true, "resume()")
	bus.run(c, DT)
	T.equal(c.state, "running", "state after resume")
	T.equal(runs.wash, 1, "times the wash began after resume")
	T.equal(bus.out.motor_rpm, 45, "motor output after resume")
	-- as after any pause, the tick that resumes counts from itself
	T.near(c:wait_left(), left, 1e-6, "time left after resume")
end)

test("reloaded again before the first restore got back to its step, it still goes on there", function()
	local bus = new_bus()
	local old = washing(bus, counts())
	old:pause()
	bus.run(old, DT)
	local left = old:wait_left()
	local first = programme(new_instance().cycle, counts())
	first:restore(reload(old))
	bus.run(first, 5)
	local runs = counts()
	local second = programme(new_instance().cycle, runs)
	T.equal(second:restore(reload(first)), true, "restore() from a restored cycle")
	second:resume()
	bus.run(second, DT)
	T.equal(runs.fill, 0, "times fill ran")
	T.equal(second.step_name, "wash", "step")
	T.near(second:wait_left(), left, 1e-6, "time left (the tick that resumes counts from itself)")
end)

test("reloaded twice while running, the time left carries over both times", function()
	local bus = new_bus()
	local old = washing(bus, counts())
	local left = old:wait_left()
	local first = programme(new_instance().cycle, counts())
	first:restore(reload(old))
	bus.run(first, 30)
	T.near(first:wait_left(), left - 30, 1e-6, "time left in the first new instance")
	local runs = counts()
	local second = programme(new_instance().cycle, runs)
	second:restore(reload(first))
	bus.run(second, DT)
	T.equal(runs.wash, 1, "times the wash began in the second new instance")
	T.near(second:wait_left(), left - 30 - DT, 1e-6, "time left in the second new instance")
end)

test("idle stays idle; a finished cycle keeps its state and error and does nothing", function()
	local bus = new_bus()
	local idle = programme(new_instance().cycle, counts())
	idle:restore(reload(programme(cycle, counts())))
	T.equal(idle.state, "idle", "state of a restored idle cycle")
	bus.out.motor_rpm = 7
	T.equal(bus.run(idle, 1), "idle", "state after ticks")
	T.equal(bus.out.motor_rpm, 7, "outputs untouched")
	T.equal(idle:start(), true, "start() after restore")

	local failing = function(cycle_module)
		return cycle_module.new({ { "fill", function(c) c:wait(1); error("valve stuck", 0) end } })
	end
	local old = failing(cycle)
	old:start()
	bus.finish(old, 5)
	T.equal(old.state, "failed", "old state")
	local c = failing(new_instance().cycle)
	c:restore(reload(old))
	T.equal(c.state, "failed", "state")
	T.equal(c.error, "fill: valve stuck", "error")
	T.equal(c.error_step, "fill", "error_step")
	T.equal(c:finished(), true, "finished()")
	bus.out.valve = true
	bus.run(c, 1)
	T.equal(bus.out.valve, true, "outputs untouched by a finished cycle")
end)

test("cancelling: the cleanup runs again from its start, from safe outputs", function()
	local bus = new_bus()
	local old = washing(bus, counts())
	old:cancel()
	bus.run(old, 2)
	T.equal(old.step_name, "pump out", "old cleanup step")
	local runs = counts()
	local c = programme(new_instance().cycle, runs)
	c:restore(reload(old))
	T.equal(c.state, "cancelling", "state")
	T.equal(c.step_name, "cleanup", "step before the first tick")
	bus.out.motor_rpm = 45
	bus.run(c, DT)
	T.equal(runs.cleanup, 1, "times the cleanup began again")
	T.equal(bus.out.pump, true, "pump output")
	T.equal(bus.out.motor_rpm, 0, "motor output (hold before the cleanup)")
	T.near(c:wait_left(), 5, 1e-6, "the cleanup's wait, from its start")
	bus.finish(c, 10)
	T.equal(c.state, "cancelled", "state at the end")
	T.equal(runs.wash + runs.drain, 0, "steps run after the cancel")
end)

test("a door interlock that was re-arming holds until the lock is confirmed", function()
	local function door(interlock_module)
		return interlock_module.new {
			name = "door open",
			trip = function(i) return not i.door_closed end,
			safe = function(o) o.motor_rpm = 0 end,
			rearm = function(o, i) o.door_lock = true; return i.door_locked end,
		}
	end
	local bus = new_bus()
	bus.inp.door_closed, bus.inp.door_locked = true, true
	local old = programme(cycle, counts(), { interlocks = { door(interlock) } })
	old:start()
	bus.run(old, 70)
	bus.inp.door_closed, bus.inp.door_locked = false, false
	bus.run(old, 1)
	bus.inp.door_closed = true
	bus.run(old, DT)
	T.equal(old.interlocks[1].state, "rearming", "old interlock")

	local new = new_instance()
	local runs = counts()
	local c = programme(new.cycle, runs, { interlocks = { door(new.interlock) } })
	c:restore(reload(old))
	T.equal(c.interlocks[1].state, "rearming", "interlock after restore")
	bus.run(c, 1)
	T.equal(c.state, "paused", "state while the lock is not confirmed")
	T.equal(runs.wash, 0, "times the wash ran before the lock")
	T.equal(bus.out.door_lock, true, "the re-arm locks the door")
	bus.inp.door_locked = true
	bus.run(c, 2 * DT)
	T.equal(c.state, "running", "state once locked")
	T.equal(runs.wash, 1, "times the wash began once locked")
end)

test("a version whose steps differ from the old one's fails into its cleanup, saying why", function()
	local bus = new_bus()
	local old = washing(bus, counts())
	local runs = counts()
	local c = new_instance().cycle.new({
		{ "fill", function(w) w:wait(10) end },
		{ "pre-wash", function(w) runs.wash = runs.wash + 1; w:wait(60) end },
		{ "wash", function(w) w:wait(240) end },
	}, { cleanup = function() runs.cleanup = runs.cleanup + 1 end })
	T.equal(c:restore(reload(old)), true, "restore()")
	bus.finish(c, 1)
	T.equal(c.error, "cycle: restore: step 2 is 'pre-wash' in this version but was 'wash' in the old one;"
		.. " cannot resume", "error")
	T.equal(runs.wash, 0, "times the mismatched step ran")
	T.equal(runs.cleanup, 1, "times the cleanup ran")
	T.equal(c.state, "failed", "state")

	local short = new_instance().cycle.new({ { "fill", function(w) w:wait(10) end } })
	short:restore(reload(old))
	bus.finish(short, 1)
	T.equal(short.state, "failed", "state of a version with fewer steps")
	T.check(short.error:find("the body ended after 1 steps", 1, true), "error of the shorter body, got %q",
		short.error)
end)

test("wait_until in the re-entered step checks again, with its whole timeout", function()
	local function filling(cycle_module)
		return cycle_module.new({ { "fill", function(c)
			c.out.valve = true
			c:wait_until(function() return c.inp.level_l >= 10 end, 30, "10 l")
			c.out.valve = false
		end } })
	end
	local bus = new_bus()
	bus.inp.level_l = 0
	local old = filling(cycle)
	old:start()
	bus.run(old, 20)
	local c = filling(new_instance().cycle)
	c:restore(reload(old))
	bus.run(c, 15)
	T.equal(c.state, "running", "state 35 s into a fill with a 30 s timeout")
	bus.inp.level_l = 10
	bus.run(c, DT)
	T.equal(c.state, "done", "state once the level is reached")
	T.equal(bus.out.valve, false, "valve output")
end)

test("restore refuses a copy that does not say how far it got, and raises on what is no cycle", function()
	local bus = new_bus()
	local copy = reload(washing(bus, counts()))
	copy.steps_begun = nil -- as from a cycle.lua that had no restore
	local c = programme(new_instance().cycle, counts())
	local ok, message = c:restore(copy)
	T.equal(ok, nil, "restore() of a copy without steps_begun")
	T.check(message:find("does not say how far it got", 1, true), "message, got %q", message)
	T.equal(c.state, "idle", "state left as it was")
	T.fails(function() c:restore(42) end, "cycle:restore: old must be a copy of a cycle", "restore(42)")
	T.fails(function() c:restore({ phase = "spinning" }) end, "cycle:restore: old must be a copy of a cycle",
		"an unknown phase")
end)

-- ---- recovery after a restart: restore(old, now) on a new bus clock ----

test("restored at a new bus clock that starts below the old one, the step goes on with the same time left",
	function()
		local bus = new_bus()
		local old = washing(bus, counts())
		local left, old_elapsed = old:wait_left(), old:elapsed()
		local runs = counts()
		local c = programme(new_instance().cycle, runs)
		T.equal(c:restore(reload(old), 2), true, "restore(old, 2)")
		T.equal(c.time, 2, "the cycle's bus time: the new clock's")
		T.near(c.started_at, old.started_at + (2 - old.time), 1e-9, "started_at, moved with the clock")
		T.near(c:wait_left(), left, 1e-9, "time left before the first tick")

		bus.t = 2 -- the bus clock started again
		bus.run(c, DT)
		T.equal(c.state, "running", "state after the first tick on the new clock (no 'time went backwards')")
		T.equal(runs.fill, 0, "times fill ran again")
		T.equal(c.step_name, "wash", "step after the first tick")
		T.near(c:wait_left(), left - DT, 1e-6, "time left after the first tick")
		T.near(c:elapsed(), old_elapsed + DT, 1e-6, "the cycle clock went on from the old one's reading")
		local ended = bus.finish(c, 400)
		T.equal(c.state, "done", "state at the end")
		T.near(ended - 2, left + 5, 2 * DT, "seconds from the restart to the end (rest of the wash, drain)")

		local again = programme(new_instance().cycle, counts())
		again:restore(reload(old))
		T.fails(function() again:tick(2, {}, {}) end, "time went backwards",
			"without now, a tick on the new clock")
		T.fails(function() again:restore(reload(old), "now") end, "cycle:restore: now must be a number",
			"restore(old, 'now')")
	end)

test("restored at a new bus clock, a paused cycle stays paused with its clock standing", function()
	local bus = new_bus()
	local old = washing(bus, counts())
	old:pause()
	bus.run(old, 5)
	local left = old:wait_left()
	local c = programme(new_instance().cycle, counts())
	c:restore(reload(old), 0)
	bus.t = 0
	bus.run(c, 3)
	T.equal(c.state, "paused", "state on the new clock")
	T.near(c:wait_left(), left, 1e-9, "time left while paused")
	c:resume()
	bus.run(c, 1)
	T.near(c:wait_left(), left - 1 + DT, 1e-6, "time left 1 s after resume (the tick that resumes counts from itself)")
end)

test("restored at a new bus clock, a re-arming interlock gets its whole re-arm timeout from then", function()
	local function door(interlock_module)
		return interlock_module.new {
			name = "door open",
			trip = function(i) return not i.door_closed end,
			safe = function(o) o.motor_rpm = 0 end,
			rearm = function(o, i) o.door_lock = true; return i.door_locked end,
			rearm_timeout = 5,
		}
	end
	local bus = new_bus()
	bus.inp.door_closed, bus.inp.door_locked = true, true
	local old = programme(cycle, counts(), { interlocks = { door(interlock) } })
	old:start()
	bus.run(old, 70)
	bus.inp.door_closed, bus.inp.door_locked = false, false
	bus.run(old, 1)
	bus.inp.door_closed = true
	bus.run(old, 4) -- 4 of its 5 s re-arming
	T.equal(old.interlocks[1].state, "rearming", "old interlock")

	local new = new_instance()
	local c = programme(new.cycle, counts(), { interlocks = { door(new.interlock) } })
	c:restore(reload(old), 1)
	T.equal(c.interlocks[1].since, 1, "the interlock's since: the new clock's now")
	bus.t = 1
	bus.run(c, 3)
	T.equal(c.interlocks[1].state, "rearming", "interlock 3 s after the restart (not in fault)")
	bus.inp.door_locked = true
	bus.run(c, 2 * DT)
	T.equal(c.state, "running", "state once locked")
end)
