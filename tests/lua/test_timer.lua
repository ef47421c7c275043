-- Tests of stdlib/timer.lua: stopwatch, pause, one-shot and periodic checks
-- in caller-supplied bus time.

local T = require "testing"
local timer = require "timer"
local test = T.test

test("elapsed counts seconds of bus time from new(now)", function()
	local t = timer.new(100)
	T.equal(t:elapsed(100), 0, "elapsed at start")
	T.near(t:elapsed(102.5), 2.5, 1e-12, "elapsed 2.5 s later")
end)

test("new(now, elapsed_s) goes on from elapsed_s, as a timer taken over from another instance", function()
	local t = timer.new(50, 12)
	T.near(t:elapsed(50), 12, 1e-12, "elapsed at start")
	T.near(t:elapsed(53), 15, 1e-12, "elapsed 3 s later")
	T.equal(t:expired(15, 53), true, "expired(15) counts the seconds it started with")
	T.fails(function() timer.new(0, -1) end, "timer.new: elapsed_s must be a number >= 0", "negative elapsed_s")
end)

test("reset restarts from zero at the given time", function()
	local t = timer.new(0)
	t:reset(10)
	T.near(t:elapsed(13), 3, 1e-12, "elapsed 3 s after reset at 10 s")
end)

test("paused time does not count, and pause/resume twice changes nothing", function()
	local t = timer.new(0)
	t:pause(4)
	t:pause(6)
	T.near(t:elapsed(9), 4, 1e-12, "elapsed while paused since 4 s")
	t:resume(10)
	t:resume(11)
	T.near(t:elapsed(12), 6, 1e-12, "elapsed at 12 s after a pause from 4 s to 10 s")
	T.equal(t:expired(6, 12), true, "expired(6) at 6 s of running time")
	T.equal(t:expired(6.5, 12), false, "expired(6.5) at 6 s of running time")
end)

test("after() is true exactly once, at the first call past the delay", function()
	local t = timer.new(0)
	local fired_at = {}
	for tick = 1, 100 do
		local now = tick * 0.1
		if t:after(5, now) then fired_at[#fired_at + 1] = now end
	end
	T.equal(#fired_at, 1, "number of times after(5) fired in 10 s")
	T.near(fired_at[1], 5, 1e-9, "time after(5) fired")
	t:reset(20)
	T.equal(t:after(5, 24.9), false, "after(5) 4.9 s after reset")
	T.equal(t:after(5, 25), true, "after(5) 5 s after reset")
end)

test("every() fires once per period with no drift over 1000 periods", function()
	local t = timer.new(0)
	local count, last = 0, nil
	-- 0.03 s ticks: 0.7 s periods do not divide evenly into ticks.
	for tick = 1, 23334 do
		local now = tick * 0.03
		if t:every(0.7, now) then
			count = count + 1
			if last then T.at_most(now - last, 0.7 + 0.03 + 1e-9, "gap between firings at %.2f s", now) end
			last = now
		end
	end
	T.equal(count, math.floor(23334 * 0.03 / 0.7), "firings of every(0.7) in 700 s")
end)

test("every() after a long gap fires once, not in a burst", function()
	local t = timer.new(0)
	T.equal(t:every(1, 0.5), false, "every(1) at 0.5 s")
	T.equal(t:every(1, 10.2), true, "every(1) at 10.2 s after missing nine periods")
	T.equal(t:every(1, 10.3), false, "every(1) again at 10.3 s")
	T.equal(t:every(1, 11), true, "every(1) at the next period end, 11 s")
end)

test("bad arguments raise errors that name the function and the argument", function()
	T.fails(function() timer.new() end, "timer.new: now must be a number", "timer.new()")
	T.fails(function() timer.new(0 / 0) end, "timer.new: now must be a number", "timer.new(NaN)")
	local t = timer.new(0)
	T.fails(function() t:elapsed("1") end, "timer:elapsed: now must be a number", "elapsed('1')")
	T.fails(function() t:after(-1, 0) end, "timer:after: seconds must be a number >= 0", "after(-1)")
	T.fails(function() t:every(0, 1) end, "timer:every: period must be a number > 0", "every(0)")
	local message = T.fails(function() t:expired(1) end, "timer:expired: now must be a number", "expired(1)")
	T.check(message:find("test_timer.lua", 1, true), "error blames the caller, got %q", message)
end)
