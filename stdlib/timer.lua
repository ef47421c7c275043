-- timer: pausable stopwatches in bus time, with one-shot and periodic checks,
-- for drivers (docs/STDLIB.md "timer"). The caller passes the time in every
-- call (seconds, e.g. inputs.time); nothing here reads a clock, so the same
-- code runs in real and in virtual time. No call allocates memory.

local type, error, floor = type, error, math.floor

local timer = {}

-- Slack on every comparison with a deadline: bus time is a sum of periods
-- and may round a little below a deadline that falls on a tick.
local EPSILON_S = 1e-9

local Timer = {}
Timer.__index = Timer

-- A time argument: a number that is not NaN. level 3 blames the caller of
-- the public function that checks it.
local function check_time(now, where)
	if type(now) ~= "number" or now ~= now then
		error(where .. ": now must be a number (seconds)", 3)
	end
end

local function check_seconds(seconds, where, what)
	if type(seconds) ~= "number" or seconds ~= seconds or seconds < 0 then
		error(where .. ": " .. what .. " must be a number >= 0 (seconds)", 3)
	end
end

-- timer.new(now, elapsed_s) -> a running timer started at now, with
-- elapsed_s seconds (default 0) already on it: a timer that continues one
-- of another instance (hot reload, cycle:restore).
function timer.new(now, elapsed_s)
	check_time(now, "timer.new")
	if elapsed_s == nil then
		elapsed_s = 0
	else
		check_seconds(elapsed_s, "timer.new", "elapsed_s")
	end
	return setmetatable({
		running = true,
		started_s = now,      -- bus time of the last (re)start or resume
		banked_s = elapsed_s, -- running time accumulated before started_s
		fired = false,        -- after() has returned true since the last reset
		next_due_s = nil,     -- every(): elapsed time of the next period end
	}, Timer)
end

local function elapsed_at(self, now)
	if self.running then
		return self.banked_s + (now - self.started_s)
	end
	return self.banked_s
end

-- Running time in seconds since the last reset, not counting paused spans.
function Timer:elapsed(now)
	check_time(now, "timer:elapsed")
	return elapsed_at(self, now)
end

-- Restart from zero at now, running, with after() and every() re-armed.
function Timer:reset(now)
	check_time(now, "timer:reset")
	self.running = true
	self.started_s = now
	self.banked_s = 0
	self.fired = false
	self.next_due_s = nil
end

-- Stop counting at now; elapsed() holds its value until resume(). A timer
-- that is already paused stays as it is.
function Timer:pause(now)
	check_time(now, "timer:pause")
	if self.running then
		self.banked_s = self.banked_s + (now - self.started_s)
		self.running = false
	end
end

-- Count again from now. A running timer stays as it is.
function Timer:resume(now)
	check_time(now, "timer:resume")
	if not self.running then
		self.started_s = now
		self.running = true
	end
end

-- Level check: true while elapsed(now) >= seconds.
function Timer:expired(seconds, now)
	check_seconds(seconds, "timer:expired", "seconds")
	check_time(now, "timer:expired")
	return elapsed_at(self, now) >= seconds - EPSILON_S
end

-- One-shot: true on the first call at which elapsed(now) >= seconds, then
-- false until reset().
function Timer:after(seconds, now)
	check_seconds(seconds, "timer:after", "seconds")
	check_time(now, "timer:after")
	if self.fired or elapsed_at(self, now) < seconds - EPSILON_S then
		return false
	end
	self.fired = true
	return true
end

-- Periodic: true once per period_s of running time, at the ends of the
-- periods counted from the last reset (no drift). A caller that missed
-- several periods gets one true, not a burst, and the next one at the next
-- period end.
function Timer:every(period_s, now)
	if type(period_s) ~= "number" or period_s ~= period_s or period_s <= 0 then
		error("timer:every: period must be a number > 0 (seconds)", 2)
	end
	check_time(now, "timer:every")
	local elapsed = elapsed_at(self, now)
	local due = self.next_due_s
	if due == nil then
		due = period_s
		self.next_due_s = due
	end
	if elapsed < due - EPSILON_S then
		return false
	end
	self.next_due_s = due + (floor((elapsed - due + EPSILON_S) / period_s) + 1) * period_s
	return true
end

return timer
