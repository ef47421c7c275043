-- Tests of stdlib/interlock.lua, alone and guarding a cycle: the washer's
-- door (open -> all off and pause; closed -> lock, then resume).

local T = require "testing"
local interlock = require "interlock"
local cycle = require "cycle"
local test = T.test

local DT = 0.1

local function all_off(out)
	out.motor_rpm = 0
	out.valve = false
	out.door_lock = false
end

-- The washer door: trips while open; re-arms by locking, done when the lock
-- input confirms.
local function door_interlock(extra)
	local spec = {
		name = "door open",
		trip = function(inp) return not inp.door_closed end,
		safe = all_off,
		rearm = function(out, inp) out.door_lock = true; return inp.door_locked end,
	}
	for k, v in pairs(extra or {}) do spec[k] = v end
	return interlock.new(spec)
end

-- A door whose lock follows the solenoid one tick late, as on the board.
local function new_machine()
	local m = { t = 0, inp = { door_closed = true, door_locked = false }, out = {} }
	function m.settle()
		m.inp.door_locked = m.inp.door_closed and m.out.door_lock == true
	end
	return m
end

test("alone: holds while tripped, re-arms after it clears, then lets go", function()
	local il = door_interlock()
	local m = new_machine()
	m.out.motor_rpm = 45
	T.equal(il:tick(0, m.inp, m.out), false, "holding with the door closed")
	T.equal(m.out.motor_rpm, 45, "outputs untouched while clear")
	m.inp.door_closed = false
	T.equal(il:tick(0.1, m.inp, m.out), true, "holding with the door open")
	T.equal(il.state, "tripped", "state with the door open")
	T.equal(m.out.motor_rpm, 0, "motor output with the door open")
	m.inp.door_closed = true
	T.equal(il:tick(0.2, m.inp, m.out), true, "holding right after the door closed")
	T.equal(il.state, "rearming", "state right after the door closed")
	T.equal(m.out.door_lock, true, "lock output while re-arming")
	T.equal(il:tick(0.25, m.inp, m.out), true, "holding while the lock is not yet confirmed")
	T.equal(il.state, "rearming", "state while the lock is not yet confirmed")
	m.settle()
	il:tick(0.3, m.inp, m.out)
	T.equal(il:tick(0.4, m.inp, m.out), false, "holding once the lock confirmed")
	T.equal(il.state, "clear", "state once the lock confirmed")
end)

test("guarding a cycle: door open pauses it with all off; closing locks, then it resumes", function()
	local il = door_interlock()
	local m = new_machine()
	local c = cycle.new({
		{ "lock", function(c)
			c.out.door_lock = true
			c:wait_until(function() return c.inp.door_locked end, 5, "door locked")
		end },
		{ "wash", function(c) c.out.motor_rpm = 45; c:wait(60) end },
		{ "unlock", function(c) c.out.motor_rpm = 0; c.out.door_lock = false end },
	}, { hold = all_off, interlocks = { il } })
	c:start()
	local opened_at, closed_at, resumed_at
	while not c:finished() and m.t < 200 do
		m.t = m.t + DT
		local t = m.t
		if t >= 20 and not opened_at then
			opened_at = t
			m.inp.door_closed = false
		elseif t >= 50 and not closed_at then
			closed_at = t
			m.inp.door_closed = true
		end
		c:tick(t, m.inp, m.out)
		m.settle()
		if opened_at and not closed_at then
			T.equal(m.out.motor_rpm, 0, "motor output with the door open at %.1f s", t)
			T.equal(c.state, "paused", "cycle state with the door open at %.1f s", t)
			T.equal(c.step_name, "wash", "step with the door open at %.1f s", t)
		end
		if closed_at and not resumed_at and c.state == "running" then
			resumed_at = t
			T.equal(m.inp.door_locked, true, "door locked when the cycle resumed at %.1f s", t)
		end
	end
	T.equal(c.state, "done", "cycle state at the end")
	T.check(resumed_at ~= nil, "the cycle resumed after the door closed")
	T.at_most(resumed_at - closed_at, 3 * DT, "seconds from door closed to resumed (lock, confirm)")
	-- 60 s of washing, plus the 30 s the door was open and the re-arm.
	T.near(m.t, 60 + 30, 6 * DT, "bus time at the end")
	T.equal(m.out.door_lock, false, "lock output at the end")
end)

test("the door open when the cycle starts: the first step waits for it to close and lock", function()
	local il = door_interlock()
	local m = new_machine()
	local started_at
	local c = cycle.new({ { "fill", function(c) started_at = c.time; c:wait(1) end } }, {
		hold = all_off, interlocks = { il },
	})
	m.inp.door_closed = false
	c:start()
	for _ = 1, 100 do
		m.t = m.t + DT
		if m.t >= 5 then m.inp.door_closed = true end
		c:tick(m.t, m.inp, m.out)
		m.settle()
	end
	T.equal(c.pause_reasons[1], nil, "pause reasons at the end")
	T.check(started_at ~= nil, "the first step began")
	T.at_least(started_at, 5, "bus time the first step began (door closed at 5 s)")
	T.at_most(started_at, 5 + 3 * DT, "bus time the first step began (door closed at 5 s)")
end)

test("a lock that does not engage: fault after rearm_timeout, retried by the next open and close", function()
	local il = door_interlock({ rearm_timeout = 2 })
	local inp, out = { door_closed = true, door_locked = false }, {}
	inp.door_closed = false
	il:tick(0, inp, out)
	inp.door_closed = true
	for tick = 1, 30 do il:tick(tick * DT, inp, out) end
	T.equal(il.state, "fault", "state after 3 s without the lock")
	T.equal(il.message, "door open: not re-armed within 2 s", "fault message")
	T.equal(il:tick(3.1, inp, out), true, "holding in fault")
	inp.door_closed = false
	il:tick(3.2, inp, out)
	inp.door_closed = true
	il:tick(3.3, inp, out)
	T.equal(il.state, "rearming", "state after the door was opened and closed again")
	T.equal(il.message, nil, "fault message cleared")
end)

test("it holds the cancel's cleanup too", function()
	local il = door_interlock()
	local m = new_machine()
	local drained_at
	local c = cycle.new({ { "wash", function(c) c:wait(100) end } }, {
		hold = all_off, interlocks = { il },
		cleanup = function(c) c.out.pump = true; c:wait(5); drained_at = c.time end,
	})
	c:start()
	local function run(seconds)
		for _ = 1, math.floor(seconds / DT + 0.5) do
			m.t = m.t + DT
			c:tick(m.t, m.inp, m.out)
			m.settle()
		end
	end
	run(2)
	m.inp.door_closed = false
	run(1)
	c:cancel()
	run(10)
	T.equal(c.state, "paused", "state: cancelling, held by the open door")
	T.equal(c.phase, "cancelling", "phase under the pause")
	T.equal(drained_at, nil, "cleanup finished with the door open")
	m.inp.door_closed = true
	run(10)
	T.equal(c.state, "cancelled", "state after the door closed")
	T.at_least(drained_at, 13 + 5, "bus time the cleanup finished")
end)

test("bad arguments raise errors naming the argument", function()
	local function noop() end
	T.fails(function() interlock.new() end, "interlock.new: expects a table", "interlock.new()")
	T.fails(function() interlock.new({ trip = noop, safe = noop }) end, "interlock.new: name must be", "no name")
	T.fails(function() interlock.new({ name = "x", safe = noop }) end, "interlock.new: trip must be a function",
		"no trip")
	T.fails(function() interlock.new({ name = "x", trip = noop }) end, "interlock.new: safe must be a function",
		"no safe")
	T.fails(function() interlock.new({ name = "x", trip = noop, safe = noop, rearm_timeout = 1 }) end,
		"interlock.new: rearm_timeout needs a rearm function", "timeout without rearm")
	local il = door_interlock()
	local message = T.fails(function() il:tick(nil, {}, {}) end, "interlock:tick: now must be a number", "tick(nil)")
	T.check(message:find("test_interlock.lua", 1, true), "error blames the caller, got %q", message)
	T.fails(function() il:update(0, nil) end, "interlock:update: inputs must be a table", "update(0, nil)")
end)
