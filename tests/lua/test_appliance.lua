-- Tests of stdlib/appliance.lua: starting programmes by name or button,
-- the service level while running, the published status, and commands.

local T = require "testing"
local appliance = require "appliance"
local cycle = require "cycle"
local host_copy = require "host_copy"
local test = T.test

-- A fake dev: records set_level calls; vars and params as a driver has them.
local function fake_dev()
	local dev = { vars = {}, params = { program = "short" }, levels = {} }
	function dev:set_level(n) self.levels[#self.levels + 1] = n; return true end
	return dev
end

-- A machine with two programmes ("short": one 1 s step; "long": one 10 s
-- step) and a door that may forbid starting. stdlib: the modules to build it
-- from (default this file's; a new driver instance loads its own).
local function machine(stdlib)
	stdlib = stdlib or { cycle = cycle, appliance = appliance }
	local m = { door_closed = true, out = {} }
	m.programs = {
		short = function(c) c:step("short step", function() c:wait(1) end) end,
		long = function(c) c:step("long step", function() c:wait(10) end) end,
	}
	m.cycle = stdlib.cycle.new(function(c) m.ctl:programme()(c) end)
	m.ctl = stdlib.appliance.new {
		cycle = m.cycle, programs = m.programs, idle_level = 5, run_level = 3,
		can_start = function() if not m.door_closed then return "close the door first" end end,
	}
	m.dev = fake_dev()
	m.t = 0
	function m.tick(start, cancel)
		m.t = m.t + 0.1
		m.ctl:buttons(m.dev, start or false, cancel or false)
		m.cycle:tick(m.t, {}, m.out)
		m.ctl:publish(m.dev)
	end
	return m
end

test("start by name runs that programme at the running level, then goes back to idle", function()
	local m = machine()
	T.equal(m.ctl:start(m.dev, "long"), true, "start long")
	T.equal(m.dev.vars.cycle, "long", "cycle variable")
	T.equal(m.dev.levels[1], 3, "level asked for on start")
	m.tick()
	T.equal(m.dev.vars.step, "long step", "step published")
	T.equal(m.dev.vars.running, true, "running published")
	T.near(m.dev.vars.time_left_s, 10, 0.11, "time left published")
	for _ = 1, 120 do m.tick() end
	T.equal(m.dev.vars.state, "done", "state after 12 s")
	T.equal(m.dev.levels[#m.dev.levels], 5, "level asked for when done")
	T.equal(#m.dev.levels, 2, "set_level calls (start, end)")
end)

test("the start button starts the default programme once per press", function()
	local m = machine()
	m.tick(true)
	T.equal(m.dev.vars.cycle, "short", "the param's programme started by the button")
	T.equal(m.dev.vars.state, "running", "state after the press")
	m.tick(true) -- still held: no second start
	T.equal(#m.dev.levels, 1, "a held button started the programme twice")
	for _ = 1, 20 do m.tick() end
	T.equal(m.dev.vars.state, "done", "short programme done after 2 s")
	m.tick(true)
	T.equal(m.dev.vars.state, "running", "a new press starts it again")
end)

test("refusals: unknown programme, can_start, already running", function()
	local m = machine()
	local ok, why = m.ctl:start(m.dev, "nosuch")
	T.equal(ok, nil, "unknown programme accepted")
	T.check(why:find("no programme 'nosuch'", 1, true), "message %q", why)
	m.door_closed = false
	ok, why = m.ctl:start(m.dev)
	T.equal(why, "close the door first", "can_start's reason")
	m.door_closed = true
	T.equal(m.ctl:start(m.dev), true, "start with the door closed")
	ok, why = m.ctl:start(m.dev, "long")
	T.equal(ok, nil, "a second start while running accepted")
	T.check(why:find("already running", 1, true), "message %q", why)
end)

test("commands and the cancel button", function()
	local m = machine()
	T.equal(m.ctl:input(m.dev, "start", "long"), true, "start command")
	m.tick()
	T.equal(m.ctl:input(m.dev, "pause", true), true, "pause command")
	m.tick()
	T.equal(m.dev.vars.state, "paused", "state after pause")
	T.equal(m.dev.vars.paused_by, "user", "paused_by")
	T.equal(m.ctl:input(m.dev, "resume", true), true, "resume command")
	m.tick()
	T.equal(m.dev.vars.state, "running", "state after resume")
	m.tick(false, true)
	m.tick()
	T.equal(m.dev.vars.state, "cancelled", "state after the cancel button")
	T.equal(m.ctl:input(m.dev, "fill_l", 12), true, "a param name is accepted as is")
	local ok = m.ctl:input(m.dev, "pause", true)
	T.equal(ok, nil, "pause with nothing running accepted")
end)

test("bad arguments raise errors naming them", function()
	T.fails(function() appliance.new() end, "expects a table", "no spec")
	T.fails(function() appliance.new { cycle = {}, programs = {}, idle_level = 1, run_level = 0 } end,
		"cycle must be a cycle", "not a cycle")
	local c = cycle.new(function() end)
	T.fails(function() appliance.new { cycle = c, programs = {}, idle_level = 1.5, run_level = 0 } end,
		"idle_level must be a whole number", "fractional level")
	T.fails(function() appliance.new { cycle = c, idle_level = 1, run_level = 0 } end,
		"programs must be a table", "no programs")
end)

test("a start refused while a programme runs leaves the running programme chosen", function()
	local m = machine()
	m.ctl:start(m.dev, "long")
	m.tick()
	local ok = m.ctl:start(m.dev, "short")
	T.equal(ok, nil, "a second start while running accepted")
	T.equal(m.ctl:programme(), m.programs.long, "the programme chosen after the refused start")
	T.equal(m.dev.vars.cycle, "long", "cycle variable after the refused start")
end)

-- A hot reload of machine m: a new machine on the same clock, restored from
-- the host's copy of m's appliance (plain data: no functions, no metatables).
-- The test runs in one driver state (tests/lua/run.c), so the new machine is
-- built from the same stdlib modules, not from a second state's own copies.
-- Returns the new machine and what restore returned.
local function reload(m, programs)
	local n = machine()
	if programs then n.ctl.programs = programs end
	n.t = m.t
	local old_state = host_copy.state({ control = m.ctl })
	return n, n.ctl:restore(old_state.control)
end

test("restore goes on with the running programme, and back to the idle level at its end", function()
	local m = machine()
	m.ctl:start(m.dev, "long")
	for _ = 1, 30 do m.tick() end
	local n, ok = reload(m)
	T.equal(ok, true, "restore()")
	n.tick()
	T.equal(n.dev.vars.cycle, "long", "cycle variable after the reload")
	T.equal(n.dev.vars.step, "long step", "step after the reload")
	T.equal(n.dev.vars.state, "running", "state after the reload")
	T.near(n.dev.vars.time_left_s, 10 - 3.1, 0.11, "time left after the reload")
	for _ = 1, 80 do n.tick() end
	T.equal(n.dev.vars.state, "done", "state at the end")
	T.equal(n.dev.levels[#n.dev.levels], 5, "level asked for at the end")
end)

test("a button held across the reload is no new press", function()
	local m = machine()
	for _ = 1, 20 do m.tick(true) end -- the short programme, started by the held button, ends
	T.equal(m.dev.vars.state, "done", "state before the reload")
	local n = reload(m)
	n.tick(true)
	T.equal(n.dev.vars.state, "done", "state after a tick with the button still held")
	T.equal(#n.dev.levels, 0, "set_level calls after the reload")
	n.tick(false)
	n.tick(true)
	T.equal(n.dev.vars.state, "running", "a new press starts it")
end)

test("restore refuses a running programme this version does not have, and changes nothing", function()
	local m = machine()
	m.ctl:start(m.dev, "long")
	m.tick()
	local n, ok, message = reload(m, { short = m.programs.short })
	T.equal(ok, nil, "restore() without the running programme")
	T.check(message:find("programme 'long' is running", 1, true), "message, got %q", message)
	T.equal(n.cycle.state, "idle", "the new cycle")
	T.equal(n.ctl.chosen, nil, "the new programme chosen")
	T.fails(function() n.ctl:restore({}) end, "appliance:restore: old must be a copy of an appliance",
		"restore({})")
end)

-- ---- checkpoints and recovery ----

test("publish asks for a checkpoint at the first publish and at each change of state or step only", function()
	local m = machine()
	local asked = 0
	function m.dev.checkpoint() asked = asked + 1 end
	m.tick()
	T.equal(asked, 1, "checkpoints after the first publish (idle)")
	m.tick()
	T.equal(asked, 1, "checkpoints after a second idle tick")
	m.programs.two = function(c)
		c:step("first", function() c:wait(1) end)
		c:step("second", function() c:wait(1) end)
	end
	m.ctl:start(m.dev, "two")
	m.tick()
	T.equal(asked, 2, "checkpoints once running its first step")
	for _ = 1, 5 do m.tick() end
	T.equal(asked, 2, "checkpoints during the first step")
	for _ = 1, 6 do m.tick() end
	T.equal(m.dev.vars.step, "second", "step after 1.1 s")
	T.equal(asked, 3, "checkpoints at the second step")
	m.ctl:input(m.dev, "pause")
	m.tick()
	T.equal(asked, 4, "checkpoints after the pause (state paused)")
	m.ctl:input(m.dev, "resume")
	for _ = 1, 20 do m.tick() end
	T.equal(m.dev.vars.state, "done", "state at the end")
	T.equal(asked, 6, "checkpoints after resume and at the end (running, done)")
end)

test("publish works on a dev without checkpoint (an older host)", function()
	local m = machine()
	T.equal(m.dev.checkpoint, nil, "the fake dev's checkpoint")
	m.ctl:start(m.dev, "short")
	m.tick()
	T.equal(m.dev.vars.state, "running", "state published")
end)

test("restore(old, now) goes on at the new clock, asks for the running level, and buttons start afresh",
	function()
		local m = machine()
		m.ctl:start(m.dev, "long")
		for _ = 1, 30 do m.tick() end
		m.ctl.last_cancel = true -- the old instance saw the cancel button down at its last tick
		local n = machine()
		local old = host_copy.state({ control = m.ctl }).control
		T.equal(n.ctl:restore(old, 0), true, "restore(old, 0)")
		n.t = 0
		n.tick()
		T.equal(n.dev.vars.state, "running", "state on the new clock")
		T.near(n.dev.vars.time_left_s, 10 - 3.1, 0.11, "time left on the new clock")
		T.equal(n.dev.levels[1], 3, "level asked for at the first publish")
		local held = machine()
		held.ctl:restore(old, 0)
		held.t = 0
		held.tick(false, true)
		T.equal(held.dev.vars.state, "cancelled",
			"a cancel button held at the first tick after a restart (a press, as at any attach)")
		T.fails(function() n.ctl:restore(old, {}) end, "appliance:restore: now must be a number", "restore(old, {})")
	end)
