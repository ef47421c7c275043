-- cycle: an appliance cycle written as a readable sequence of named steps
-- and run as a coroutine across driver ticks (docs/STDLIB.md "cycle"), with
-- pause/resume, cancel with a cleanup, interlocks and failure by step.
-- Needs `coroutine` in the sandbox. Time comes only from tick(now, ...): the
-- cycle clock counts running time in seconds and stands still while paused.

local timer = require "timer"

local type, error, tostring, pairs, ipairs = type, error, tostring, pairs, ipairs
local create, resume, yield, running, status =
	coroutine.create, coroutine.resume, coroutine.yield, coroutine.running, coroutine.status

local cycle = {}

local Cycle = {}
Cycle.__index = Cycle

local USER = "user" -- the pause reason of pause() and resume() without one

-- Slack on deadlines, so that wait(10) at 0.1 s ticks takes 100 ticks even
-- when the sums of bus time round a little below.
local EPSILON_S = 1e-9

local ACTIVE = { running = true, cancelling = true }
local FINISHED = { done = true, cancelled = true, failed = true }

local function is_number(x)
	return type(x) == "number" and x == x
end

-- The default hold: every boolean output of the cycle off, every number 0.
local function hold_all_off(outputs, c)
	for name, value in pairs(c.out) do
		local kind = type(value)
		if kind == "boolean" then
			outputs[name] = false
		elseif kind == "number" then
			outputs[name] = 0
		end
	end
end

local function update_state(c)
	if ACTIVE[c.phase] and #c.pause_reasons > 0 then
		c.state = "paused"
	else
		c.state = c.phase
	end
end

-- Only the cycle's own coroutine may wait; where names the method, level
-- is error()'s level for the caller of that method.
local function check_inside(c, where, level)
	if c.co == nil or running() ~= c.co then
		error("cycle:" .. where .. ": call it only from inside the cycle's steps", level + 1)
	end
end

-- Remove a pause reason; true if it was set. Allocates nothing, as the
-- interlocks call it every tick.
local function remove_reason(c, reason)
	local reasons = c.pause_reasons
	for i = 1, #reasons do
		if reasons[i] == reason then
			table.remove(reasons, i)
			update_state(c)
			return true
		end
	end
	return false
end

-- A step list {{name, fn}, ...} (or {name = , run = }) as one body function.
local function list_body(list)
	local steps, names = {}, {}
	for index, item in ipairs(list) do
		local name, fn
		if type(item) == "table" then
			name, fn = item.name or item[1], item.run or item[2]
		end
		if type(name) ~= "string" or type(fn) ~= "function" then
			error("cycle.new: step " .. index .. " must be {name, function(c) ... end}", 3)
		end
		steps[index] = { name, fn }
		names[index] = name
	end
	if #steps == 0 then
		error("cycle.new: the step list is empty", 3)
	end
	return function(c)
		for _, item in ipairs(steps) do
			c:step(item[1], item[2])
		end
	end, names
end

-- cycle.new(body, options) -> a cycle in state "idle". body is
-- function(c) ... end calling c:step(name, fn), or a list of steps
-- {{"fill", function(c) ... end}, ...}. options (all optional): cleanup
-- function(c), hold function(outputs, c), interlocks {il, ...}, steps {names},
-- outputs {name = initial value}.
function cycle.new(body, options)
	local names
	if type(body) == "table" then
		body, names = list_body(body)
	elseif type(body) ~= "function" then
		error("cycle.new: body must be a function(c) or a list of {name, function(c)} steps", 2)
	end
	if options == nil then
		options = {}
	elseif type(options) ~= "table" then
		error("cycle.new: options must be a table", 2)
	end
	local cleanup, hold = options.cleanup, options.hold
	if cleanup ~= nil and type(cleanup) ~= "function" then
		error("cycle.new: cleanup must be a function(c)", 2)
	end
	if hold ~= nil and type(hold) ~= "function" then
		error("cycle.new: hold must be a function(outputs, c)", 2)
	end
	local interlocks = options.interlocks or {}
	if type(interlocks) ~= "table" then
		error("cycle.new: interlocks must be a list of interlocks", 2)
	end
	for index, il in ipairs(interlocks) do
		if type(il) ~= "table" or type(il.update) ~= "function" or type(il.apply) ~= "function"
			or type(il.name) ~= "string" then
			error("cycle.new: interlocks[" .. index .. "] is not an interlock (interlock.new)", 2)
		end
	end
	if options.steps ~= nil then
		if names ~= nil then
			error("cycle.new: options.steps is for a body function; a step list names its steps", 2)
		end
		if type(options.steps) ~= "table" then
			error("cycle.new: steps must be a list of step names", 2)
		end
		names = {}
		for index, name in ipairs(options.steps) do
			if type(name) ~= "string" then
				error("cycle.new: steps[" .. index .. "] must be a string", 2)
			end
			names[index] = name
		end
	end
	local out = {}
	if options.outputs ~= nil then
		if type(options.outputs) ~= "table" then
			error("cycle.new: outputs must be a table of initial output values", 2)
		end
		for name, value in pairs(options.outputs) do
			out[name] = value
		end
	end
	local c = setmetatable({
		body = body, cleanup = cleanup, hold = hold or hold_all_off, interlocks = interlocks,
		steps = names or {}, declared_steps = names ~= nil,
		out = out, pause_reasons = {},
		phase = "idle", state = "idle",
	}, Cycle)
	return c
end

-- ---- control, from the driver (any time) ----

-- Arm the cycle; it begins at the next tick. A finished cycle starts over.
-- Returns true, or nil and a message when it is running.
function Cycle:start()
	if ACTIVE[self.phase] then
		return nil, "cycle is already " .. self.phase
	end
	local body = self.body
	self.co = create(function() body(self) end)
	self.phase = "running"
	self.error, self.error_step = nil, nil
	self.step_name, self.step_index, self.in_step = nil, 0, false
	self.step_started_s = 0
	self.wait_until_s = nil
	self.clock, self.time, self.dt, self.started_at = nil, nil, 0, nil
	self.pause_reasons = {}
	self.hold_pending, self.flush_pending = false, false
	if not self.declared_steps then
		self.steps = {}
	end
	for _, il in ipairs(self.interlocks) do
		il:reset()
	end
	update_state(self)
	return true
end

-- Pause for a reason (default "user"); the cycle stays paused while any
-- reason is set. Takes effect at the next tick (from inside a step: when the
-- step next waits). Returns true, or nil and a message when not running.
function Cycle:pause(reason)
	reason = reason or USER
	if type(reason) ~= "string" then
		error("cycle:pause: reason must be a string", 2)
	end
	if not ACTIVE[self.phase] then
		return nil, "cycle is not running"
	end
	local reasons = self.pause_reasons
	for i = 1, #reasons do
		if reasons[i] == reason then return true end
	end
	reasons[#reasons + 1] = reason
	update_state(self)
	return true
end

-- Clear a pause reason (default "user"). Returns true, or nil and a
-- message when the cycle was not paused for that reason.
function Cycle:resume(reason)
	reason = reason or USER
	if type(reason) ~= "string" then
		error("cycle:resume: reason must be a string", 2)
	end
	if remove_reason(self, reason) then
		return true
	end
	return nil, "cycle is not paused by " .. reason
end

-- Leave the steps: into the cleanup if there is one, else finished. The
-- outputs c.out become safe (hold) within the tick: at once when this
-- happens inside a tick, else at the start of the next one.
local function stop(c)
	c.hold_pending = true
	c.in_step = false
	c.wait_until_s = nil
	c.step_started_s = c:elapsed()
	if c.cleanup then
		local cleanup = c.cleanup
		c.phase = "cancelling"
		c.step_name = "cleanup"
		c.co = create(function() cleanup(c) end)
	else
		c.phase = c.error and "failed" or "cancelled"
		c.co = nil
		c.flush_pending = true
	end
	update_state(c)
end

-- Stop the steps and run the cleanup to its end (state "cancelling", then
-- "cancelled"). The user's pause is cleared; interlocks still hold the
-- cleanup. Returns true, or nil and a message when there is nothing to cancel.
function Cycle:cancel()
	if self.phase ~= "running" then
		if self.phase == "cancelling" then
			return nil, "cycle is already cancelling"
		end
		return nil, "cycle is not running"
	end
	local inside = self.co ~= nil and running() == self.co
	remove_reason(self, USER)
	stop(self)
	if inside then
		yield() -- the cancelled steps never run again
	end
	return true
end

-- An error from the coroutine. It is blamed on the step it happened in;
-- outside any step on "cleanup" in the cleanup, else on "cycle".
local function fail(c, message)
	message = tostring(message)
	local step = "cycle"
	if c.in_step then
		step = c.step_name
	elseif c.phase == "cancelling" then
		step = "cleanup"
	end
	if c.phase == "running" then
		c.error, c.error_step = step .. ": " .. message, step
		stop(c)
	else -- the cleanup failed
		local text = step .. ": " .. message
		if c.error then
			c.error = c.error .. "; then in cleanup, " .. text
		else
			c.error, c.error_step = text, step
		end
		c.phase, c.co = "failed", nil
		c.hold_pending = true
	end
end

local function finish(c)
	if c.phase == "running" then
		c.phase = "done"
	else
		c.phase = c.error and "failed" or "cancelled"
	end
	c.co = nil
	c.in_step = false
	c.hold_pending = true
end

-- One tick of the cycle. now: bus time in seconds (never decreasing);
-- inputs: the driver's named inputs (c.inp during the tick); outputs: the
-- driver's named outputs, written while the cycle is active and once more
-- when it finishes. Returns c.state.
function Cycle:tick(now, inputs, outputs)
	if not is_number(now) then
		error("cycle:tick: now must be a number (bus time, seconds)", 2)
	end
	if type(inputs) ~= "table" then
		error("cycle:tick: inputs must be a table", 2)
	end
	if type(outputs) ~= "table" then
		error("cycle:tick: outputs must be a table", 2)
	end
	if self.time ~= nil and now < self.time then
		error("cycle:tick: time went backwards (" .. now .. " s after " .. self.time .. " s)", 2)
	end
	local phase = self.phase
	if not ACTIVE[phase] and not self.flush_pending then
		return self.state
	end

	self.inp = inputs
	self.dt = self.time and now - self.time or 0
	self.time = now
	if self.clock == nil then
		self.clock = timer.new(now)
		self.started_at = now
	end

	if ACTIVE[phase] then
		for _, il in ipairs(self.interlocks) do
			if il:update(now, inputs) then
				self:pause(il.name)
			else
				remove_reason(self, il.name)
			end
		end
		if #self.pause_reasons > 0 then
			self.clock:pause(now)
		else
			self.clock:resume(now)
		end
		if self.hold_pending then
			self.hold_pending = false
			self.hold(self.out, self)
		end
		if #self.pause_reasons == 0 then
			local co = self.co
			local ok, message = resume(co, self)
			if not ok then
				fail(self, message)
			elseif status(co) == "dead" and self.co == co then
				finish(self)
			end
		end
		update_state(self)
	end
	if self.hold_pending then
		self.hold_pending = false
		self.hold(self.out, self)
	end

	for name, value in pairs(self.out) do
		outputs[name] = value
	end
	if ACTIVE[self.phase] then
		if #self.pause_reasons > 0 then
			self.hold(outputs, self)
		end
		for _, il in ipairs(self.interlocks) do
			il:apply(outputs, inputs)
		end
	else
		self.flush_pending = false
	end
	return self.state
end

-- ---- status, for the driver and its UI ----

-- Running seconds since the cycle began (0 before its first tick); time
-- paused does not count.
function Cycle:elapsed()
	if self.clock == nil then return 0 end
	return self.clock:elapsed(self.time)
end

-- Running seconds since the current step began.
function Cycle:step_elapsed()
	return self:elapsed() - self.step_started_s
end

-- Running seconds left in the current wait(), or nil when not in one.
function Cycle:wait_left()
	if self.wait_until_s == nil then return nil end
	local left = self.wait_until_s - self:elapsed()
	return left > 0 and left or 0
end

-- True while running, paused or cancelling.
function Cycle:active()
	return ACTIVE[self.phase] == true
end

-- True once done, cancelled or failed.
function Cycle:finished()
	return FINISHED[self.phase] == true
end

-- ---- inside the steps ----

local function step_position(c, name)
	local steps = c.steps
	for i = c.step_index + 1, #steps do
		if steps[i] == name then return i end
	end
	for i = 1, #steps do
		if steps[i] == name then return i end
	end
	steps[#steps + 1] = name
	return #steps
end

-- Run fn(c) as the step called name (c.step_name, c.step_index); returns
-- what fn returns. Steps do not nest.
function Cycle:step(name, fn)
	if type(name) ~= "string" then
		error("cycle:step: name must be a string", 2)
	end
	if type(fn) ~= "function" then
		error("cycle:step: step " .. name .. " needs a function(c)", 2)
	end
	check_inside(self, "step", 2)
	if self.in_step then
		error("cycle:step: step " .. name .. " inside step " .. self.step_name .. "; steps do not nest", 2)
	end
	self.step_name = name
	if self.phase == "running" then
		self.step_index = step_position(self, name)
	end
	self.step_started_s = self:elapsed()
	self.in_step = true
	-- fn's results pass through; an error propagates and fails the cycle.
	local function finish_step(...)
		self.in_step = false
		return ...
	end
	return finish_step(fn(self))
end

-- Wait for the next tick.
function Cycle:yield()
	check_inside(self, "yield", 2)
	yield()
end

-- Wait seconds of running time (paused time does not count). wait(0)
-- returns at once.
function Cycle:wait(seconds)
	if not is_number(seconds) or seconds < 0 then
		error("cycle:wait: seconds must be a number >= 0", 2)
	end
	check_inside(self, "wait", 2)
	local deadline = self:elapsed() + seconds
	self.wait_until_s = deadline
	while self:elapsed() < deadline - EPSILON_S do
		yield()
	end
	self.wait_until_s = nil
end

local function await(c, condition, timeout_s, where)
	if type(condition) ~= "function" then
		error("cycle:" .. where .. ": condition must be a function", 3)
	end
	if timeout_s ~= nil and (not is_number(timeout_s) or timeout_s < 0) then
		error("cycle:" .. where .. ": timeout must be a number >= 0 (seconds) or nil", 3)
	end
	check_inside(c, where, 3)
	local deadline = timeout_s and c:elapsed() + timeout_s
	while not condition(c) do
		if deadline and c:elapsed() >= deadline - EPSILON_S then
			return false
		end
		yield()
	end
	return true
end

-- Wait until condition(c) is true, checked now and then once per tick.
-- After timeout_s seconds of running time (nil: no limit) it raises
-- "timed out after N s waiting for <what>", which fails the cycle in the
-- current step.
function Cycle:wait_until(condition, timeout_s, what)
	if not await(self, condition, timeout_s, "wait_until") then
		error("timed out after " .. timeout_s .. " s waiting for " .. (what or "condition"), 0)
	end
end

-- Like wait_until, but returns true when the condition came true and false
-- on timeout, for steps that handle a timeout themselves.
function Cycle:try_wait_until(condition, timeout_s)
	return await(self, condition, timeout_s, "try_wait_until")
end

return cycle
