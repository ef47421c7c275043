-- Tests of stdlib/ramp.lua: the setpoint generator never exceeds its rate
-- and acceleration limits (as seen from its outputs alone), reaches its
-- target, and takes as long as ramp.profile says.

local T = require "testing"
local ramp = require "ramp"
local test = T.test

local DT = 0.03
local SLACK = 1e-6 -- relative, for floating-point rounding

-- Runs r toward target(t) for seconds and checks every step against the
-- limits, from the values alone: rate = dvalue/dt, and the change of rate
-- per second, split into speeding up (<= accel) and slowing down (<= decel).
-- Returns the time at which done() first became true (or nil) and the peak
-- |rate|.
local function run_checked(r, limits, target, seconds, dt)
	dt = dt or DT
	local t, value, rate = 0, r.value, 0
	local done_at, peak_rate = nil, 0
	local accel, decel, max_rate = limits.accel, limits.decel or limits.accel, limits.max_rate or math.huge
	for _ = 1, math.floor(seconds / dt + 0.5) do
		local goal = type(target) == "function" and target(t) or target
		local new_value = r:update(goal, dt)
		t = t + dt
		local new_rate = (new_value - value) / dt
		T.at_most(math.abs(new_rate), max_rate * (1 + SLACK), "|rate| at t=%.2f s", t)
		local speeding = math.abs(new_rate) - math.abs(rate)
		if new_rate * rate < 0 then
			T.at_most(math.abs(rate) / dt, decel * (1 + SLACK), "braking through zero at t=%.2f s", t)
			T.at_most(math.abs(new_rate) / dt, accel * (1 + SLACK), "speeding up through zero at t=%.2f s", t)
		elseif speeding > 0 then
			T.at_most(speeding / dt, accel * (1 + SLACK), "acceleration at t=%.2f s (value %.4f)", t, new_value)
		else
			T.at_most(-speeding / dt, decel * (1 + SLACK), "deceleration at t=%.2f s (value %.4f)", t, new_value)
		end
		if math.abs(new_rate) > peak_rate then peak_rate = math.abs(new_rate) end
		value, rate = new_value, new_rate
		if done_at == nil and r:done() then done_at = t end
	end
	return done_at, peak_rate
end

test("drum spin-up 0 -> 400 RPM at 50 RPM/s: limits hold, no overshoot, done in the profile's time", function()
	local limits = { accel = 100, max_rate = 50 }
	local r = ramp.new(limits)
	local highest = 0
	local done_at = run_checked(r, limits, function()
		if r.value > highest then highest = r.value end
		return 400
	end, 12)
	T.equal(r.value, 400, "value after 12 s")
	T.equal(r:done(), true, "done() after 12 s")
	T.at_most(highest, 400, "highest value on the way (overshoot)")
	local plan = ramp.profile({ accel = 100, max_rate = 50, from = 0, to = 400 })
	T.near(done_at, plan.total_s, 2 * DT, "time to reach 400 RPM vs ramp.profile's %.3f s", plan.total_s)
end)

test("different accel and decel: speeding up within accel, slowing within decel", function()
	local limits = { accel = 3, decel = 1, max_rate = 2 }
	local r = ramp.new(limits)
	local done_at = run_checked(r, limits, 10, 20, 0.01)
	T.equal(r.value, 10, "value after 20 s")
	local plan = ramp.profile({ accel = 3, decel = 1, max_rate = 2, from = 0, to = 10 })
	T.near(done_at, plan.total_s, 0.03, "time to reach 10")
end)

test("a short move never reaches max_rate (triangular profile)", function()
	local limits = { accel = 100, max_rate = 50 }
	local r = ramp.new(limits)
	local _, peak = run_checked(r, limits, 10, 3)
	local plan = ramp.profile({ accel = 100, max_rate = 50, from = 0, to = 10 })
	T.equal(plan.cruise_s, 0, "cruise time of a 10 RPM move")
	T.near(peak, plan.peak_rate, 100 * DT, "peak rate of the move")
	T.at_most(peak, 50 - 10, "peak rate stays well under max_rate")
	T.equal(r.value, 10, "value after 3 s")
end)

test("the target may change mid-move, even reverse, and the limits still hold", function()
	local limits = { accel = 100, decel = 60, max_rate = 50 }
	local r = ramp.new(limits)
	run_checked(r, limits, function(t)
		if t < 3 then return 400 elseif t < 6 then return -45 else return 45 end
	end, 12)
	T.equal(r.value, 45, "value after the target went 400, -45, 45")
	T.equal(r:done(), true, "done() at 45")
end)

test("accel = math.huge makes a plain rate limiter", function()
	local limits = { accel = math.huge, max_rate = 50 }
	local r = ramp.new(limits)
	local t = 0
	repeat
		r:update(400, DT)
		t = t + DT
	until r:done() or t > 20
	T.near(t, 400 / 50, 2 * DT, "time from 0 to 400 at 50 units/s, at rest")
	T.near(r:update(0, DT), 400 - 50 * DT, 1e-9, "first step back down")
end)

test("reset sets the value at rest; dt == 0 changes nothing", function()
	local r = ramp.new({ accel = 10, value = 5 })
	T.equal(r.value, 5, "initial value")
	T.equal(r:done(), true, "done() at rest at the start")
	r:update(100, 1)
	r:reset(42)
	T.equal(r.value, 42, "value after reset(42)")
	T.equal(r.rate, 0, "rate after reset")
	T.equal(r:update(0, 0), 42, "value after update with dt = 0")
	T.equal(r:done(), false, "done() with a new target not yet reached")
end)

test("ramp.profile: 0 -> 400 at 50 units/s with 100 units/s^2 is 0.5 + 7.5 + 0.5 s", function()
	local plan = ramp.profile({ accel = 100, max_rate = 50, from = 0, to = 400 })
	T.near(plan.accel_s, 0.5, 1e-12, "accel_s")
	T.near(plan.cruise_s, 7.5, 1e-12, "cruise_s")
	T.near(plan.decel_s, 0.5, 1e-12, "decel_s")
	T.near(plan.total_s, 8.5, 1e-12, "total_s")
	T.equal(plan.peak_rate, 50, "peak_rate")
	local down = ramp.profile({ accel = 2, decel = 1, from = 10, to = 4 })
	-- No max_rate: peak = sqrt(2 * 6 * a * d / (a + d)) = sqrt(8)
	T.near(down.peak_rate, math.sqrt(8), 1e-12, "peak_rate of a move with no max_rate")
	T.near(down.total_s, math.sqrt(8) / 2 + math.sqrt(8), 1e-12, "total_s of a move with no max_rate")
end)

test("bad arguments raise errors naming the argument, blamed on the caller", function()
	T.fails(function() ramp.new() end, "ramp.new: expects a table", "ramp.new()")
	local message = T.fails(function() ramp.new({}) end, "ramp.new: accel must be a number > 0", "no accel")
	T.check(message:find("test_ramp.lua", 1, true), "error blames the caller, got %q", message)
	T.fails(function() ramp.new({ accel = 1, decel = 0 }) end, "ramp.new: decel must be a number > 0", "decel 0")
	T.fails(function() ramp.new({ accel = 1, max_rate = -1 }) end, "ramp.new: max_rate must be a number > 0",
		"max_rate < 0")
	T.fails(function() ramp.new({ accel = 1, value = "0" }) end, "ramp.new: value must be a number", "value '0'")
	T.fails(function() ramp.profile({ accel = 1, from = 0 }) end, "ramp.profile: from and to must be numbers",
		"profile without to")
	local r = ramp.new({ accel = 1 })
	T.fails(function() r:update(0 / 0, DT) end, "ramp:update: target must be a number", "target NaN")
	T.fails(function() r:update(1, -1) end, "ramp:update: dt must be a number >= 0", "dt < 0")
	T.fails(function() r:reset() end, "ramp:reset: value must be a number", "reset()")
end)
