-- cycle: an appliance cycle written as a readable sequence of named steps
-- and run as a coroutine across driver ticks (docs/STDLIB.md "cycle"), with
-- pause/resume, cancel with a cleanup, interlocks and failure by step.
-- Needs `coroutine` in the sandbox. Time comes only from tick(now, ...): the
-- cycle clock counts running time in seconds and stands still while paused.
-- restore() continues in a new instance of the driver (hot reload, or
-- recovery from a checkpoint after a restart) a cycle of the old one, from a
-- plain copy of it: the body runs again, skipping the steps the old instance
-- had finished.

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
local PHASES = { idle = true, running = true, cancelling = true, done = true, cancelled = true, failed = true }

local function is_number(x)
	return type(x) == "number" and x == x
end

local function number_or(x, default)
	if is_number(x) then return x end
	return default
end

local function string_or_nil(x)
	if type(x) == "string" then return x end
	return nil
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

-- The coroutine of the steps. A restored cycle (restore) replays the body
-- from its start: a body that ends before it got back to where the old
-- instance was is not the body the old instance ran.
local function run_body(c)
	if c.replay ~= nil then
		c.step_index = 0 -- found again step by step, as the old instance found them
	end
	c.body(c)
	local replay = c.replay
	if replay ~= nil then
		error("restore: the body ended after " .. c.steps_begun .. " steps, but the old version was at step "
			.. replay.steps_begun .. " (" .. tostring(replay.step_name) .. "); cannot resume", 0)
	end
end

local function run_cleanup(c)
	c.cleanup(c)
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
		-- Where the coroutine is, in plain data that a hot reload copies
		-- (restore): steps begun since start (or since the cleanup began),
		-- seconds of the wait() calls finished since the last step boundary,
		-- and the cycle time at which the current wait began.
		steps_begun = 0, segment_waited_s = 0, wait_started_s = nil,
		-- After restore: credit_s, seconds of waiting the old instance had
		-- done in this step, taken off its waits; replay, until the body is
		-- back where the old instance was, that position (restore).
		credit_s = 0, replay = nil,
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
	self.co = create(run_body)
	self.phase = "running"
	self.error, self.error_step = nil, nil
	self.step_name, self.step_index, self.in_step = nil, 0, false
	self.step_started_s = 0
	self.wait_until_s, self.wait_started_s = nil, nil
	self.steps_begun, self.segment_waited_s, self.credit_s, self.replay = 0, 0, 0, nil
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
	c.wait_until_s, c.wait_started_s = nil, nil
	c.steps_begun, c.segment_waited_s, c.credit_s, c.replay = 0, 0, 0, nil
	c.step_started_s = c:elapsed()
	if c.cleanup then
		c.phase = "cancelling"
		c.step_name = "cleanup"
		c.co = create(run_cleanup)
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

-- The end of a step, passing fn's results through.
local function end_step(c, ...)
	c.in_step = false
	c.segment_waited_s, c.credit_s = 0, 0
	return ...
end

-- A restored cycle is back where the old instance was: from here on it runs
-- for real, and its waits take off what the old instance had waited since
-- the last step boundary (replay.waited_s, plus the wait it was in).
local function arrive(c, replay)
	c.replay = nil
	c.step_started_s = replay.step_started_s
	local credit = replay.waited_s
	local wait_started = replay.wait_started_s
	if wait_started ~= nil then
		local into = c:elapsed() - wait_started
		if into > 0 then credit = credit + into end
	end
	c.segment_waited_s, c.credit_s = 0, credit
	c.wait_until_s, c.wait_started_s = nil, nil
end

-- Run fn(c) as the step called name (c.step_name, c.step_index); returns
-- what fn returns. Steps do not nest. While a restored cycle replays its
-- body, the steps the old instance had finished return at once (nil), and
-- the one it was in runs again from its beginning.
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
	local begun = self.steps_begun + 1
	self.steps_begun = begun
	self.step_name = name
	if self.phase == "running" then
		self.step_index = step_position(self, name)
	end
	local replay = self.replay
	if replay ~= nil and begun <= replay.steps_begun then
		if begun < replay.steps_begun then
			return -- the old instance finished this step
		end
		if name ~= replay.step_name then
			error("restore: step " .. begun .. " is '" .. name .. "' in this version but was '"
				.. tostring(replay.step_name) .. "' in the old one; cannot resume", 0)
		end
		if not replay.in_step then
			arrive(self, replay) -- the old instance was past the end of this step
			return
		end
		self.in_step = true
		arrive(self, replay)
	else
		self.step_started_s = self:elapsed()
		self.in_step = true
		self.segment_waited_s, self.credit_s = 0, 0
	end
	-- fn's results pass through; an error propagates and fails the cycle.
	return end_step(self, fn(self))
end

-- Wait for the next tick. (Replaying a restored cycle: at once.)
function Cycle:yield()
	check_inside(self, "yield", 2)
	if self.replay ~= nil then return end
	yield()
end

-- Wait seconds of running time (paused time does not count). wait(0)
-- returns at once. In a restored step, the old instance's waiting (credit_s)
-- counts as waited; replaying a restored cycle, it returns at once.
function Cycle:wait(seconds)
	if not is_number(seconds) or seconds < 0 then
		error("cycle:wait: seconds must be a number >= 0", 2)
	end
	check_inside(self, "wait", 2)
	if self.replay ~= nil then return end
	local credit = self.credit_s
	local taken = credit < seconds and credit or seconds
	self.credit_s = credit - taken
	local started = self:elapsed() - taken -- as if it had begun taken seconds ago
	local deadline = started + seconds
	self.wait_started_s, self.wait_until_s = started, deadline
	while self:elapsed() < deadline - EPSILON_S do
		yield()
	end
	self.wait_started_s, self.wait_until_s = nil, nil
	self.segment_waited_s = self.segment_waited_s + seconds
end

local function await(c, condition, timeout_s, where)
	if type(condition) ~= "function" then
		error("cycle:" .. where .. ": condition must be a function", 3)
	end
	if timeout_s ~= nil and (not is_number(timeout_s) or timeout_s < 0) then
		error("cycle:" .. where .. ": timeout must be a number >= 0 (seconds) or nil", 3)
	end
	check_inside(c, where, 3)
	if c.replay ~= nil then
		return true -- replaying a restored cycle: the old instance got past this
	end
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

-- ---- hot reload: continue the cycle of an old instance ----

-- Running seconds on a copied cycle's clock at its last tick, or nil when
-- it never ticked. The clock arrives as a plain table (timer's fields).
local function copied_elapsed(old)
	local clock, time = old.clock, old.time
	if type(clock) ~= "table" or not is_number(time) then return nil end
	local elapsed = number_or(clock.banked_s, 0)
	if clock.running == true and is_number(clock.started_s) then
		elapsed = elapsed + (time - clock.started_s)
	end
	return elapsed > 0 and elapsed or 0
end

-- Where a copied running cycle was in its body, as a replay position (all
-- times on the cycle clock, which restore continues), or nil when the copy
-- does not say.
local function replay_position(old)
	local pos = old.replay
	if type(pos) ~= "table" then -- the coroutine's own position
		if not is_number(old.steps_begun) then return nil end
		local wait_started = number_or(old.wait_started_s, nil)
		pos = {
			steps_begun = old.steps_begun, step_name = old.step_name, in_step = old.in_step,
			step_started_s = old.step_started_s,
			-- waits finished since the last step boundary, and credit not yet used
			waited_s = number_or(old.segment_waited_s, 0) + number_or(old.credit_s, 0),
			wait_started_s = wait_started,
		}
	end -- else: itself restored and not yet back where its old instance was
	if not is_number(pos.steps_begun) or pos.steps_begun < 0
		or (pos.steps_begun > 0 and type(pos.step_name) ~= "string") then
		return nil
	end
	return {
		steps_begun = pos.steps_begun, step_name = pos.step_name, in_step = pos.in_step == true,
		step_started_s = number_or(pos.step_started_s, 0), waited_s = number_or(pos.waited_s, 0),
		wait_started_s = number_or(pos.wait_started_s, nil),
	}
end

-- The pause reasons to keep: the old ones, but not those of an interlock
-- the old instance had and this one has not (nothing would clear them).
local function kept_reasons(c, old)
	local mine, dropped = {}, {}
	for _, il in ipairs(c.interlocks) do mine[il.name] = true end
	if type(old.interlocks) == "table" then
		for _, il in ipairs(old.interlocks) do
			if type(il) == "table" and type(il.name) == "string" and not mine[il.name] then
				dropped[il.name] = true
			end
		end
	end
	local reasons, seen = {}, {}
	if type(old.pause_reasons) == "table" then
		for _, reason in ipairs(old.pause_reasons) do
			if type(reason) == "string" and not dropped[reason] and not seen[reason] then
				seen[reason] = true
				reasons[#reasons + 1] = reason
			end
		end
	end
	return reasons
end

-- Take over the cycle of the old instance of the driver (hot reload); old
-- is the plain-data copy of that cycle object found in migrate's old_state
-- (functions, coroutines and metatables dropped). Finished or idle: its
-- status is taken over. Running: the body starts again and replays to where
-- the old one was (docs/STDLIB.md "cycle", "Hot reload"). Cancelling: the
-- cleanup runs again from its start. Call it before the first tick of the
-- new instance. now (optional, seconds): the bus time the new instance goes
-- on from when it is not the old one's, after a restart (docs/STDLIB.md
-- "Recovery"): the clock continues its elapsed running time from now, the
-- bus times taken over move by now - old.time, and the interlocks' states
-- count from now (il:restore). Without it the bus clock is the old one's
-- (hot reload). Returns true, or nil and a message
-- when the copy does not say where a running cycle was (this object is then
-- unchanged).
function Cycle:restore(old, now)
	if type(old) ~= "table" or not PHASES[old.phase] then
		error("cycle:restore: old must be a copy of a cycle (a table with its phase)", 2)
	end
	if now ~= nil and not is_number(now) then
		error("cycle:restore: now must be a number (bus time, seconds) or nil", 2)
	end
	if self.co ~= nil and running() == self.co then
		error("cycle:restore: call it from the driver (migrate), not from the cycle's steps", 2)
	end
	local phase = old.phase
	local position
	if phase == "running" then
		position = replay_position(old)
		if position == nil then
			return nil, "cycle:restore: the old cycle is running but its copy does not say how far it got"
				.. " (no steps_begun: a cycle.lua without restore)"
		end
	end

	-- The clock goes on from the old one's elapsed time at its last tick,
	-- at the old bus time or at now. Waits, the step's start and the replay
	-- position are on the cycle clock and need no moving; the bus times
	-- (time, started_at) move with it.
	local elapsed = copied_elapsed(old)
	if elapsed ~= nil then
		local at = now or old.time
		self.time = at
		self.clock = timer.new(at, elapsed)
		if old.clock.running ~= true then
			self.clock:pause(at)
		end
		local started_at = number_or(old.started_at, nil)
		self.started_at = started_at and started_at + (at - old.time)
	else
		self.time, self.clock, self.started_at = nil, nil, nil
	end
	self.dt = 0

	-- The outputs the steps had set: the names this version declares (all,
	-- when it declares none).
	local declared = next(self.out) ~= nil
	if type(old.out) == "table" then
		for name, value in pairs(old.out) do
			local kind = type(value)
			if (kind == "boolean" or kind == "number" or kind == "string")
				and (not declared or self.out[name] ~= nil) then
				self.out[name] = value
			end
		end
	end
	if not self.declared_steps then
		local steps = {}
		if type(old.steps) == "table" then
			for index, name in ipairs(old.steps) do
				if type(name) ~= "string" then break end
				steps[index] = name
			end
		end
		self.steps = steps
	end
	if type(old.interlocks) == "table" then
		for _, il in ipairs(self.interlocks) do
			for _, old_il in ipairs(old.interlocks) do
				if type(old_il) == "table" and old_il.name == il.name then
					il:restore(old_il, now)
					break
				end
			end
		end
	end

	self.phase = phase
	self.co = nil
	self.error, self.error_step = string_or_nil(old.error), string_or_nil(old.error_step)
	self.step_name = string_or_nil(old.step_name)
	self.step_index = number_or(old.step_index, 0)
	self.in_step = false
	self.step_started_s = number_or(old.step_started_s, 0)
	self.wait_until_s, self.wait_started_s = nil, nil
	self.steps_begun, self.segment_waited_s, self.credit_s, self.replay = 0, 0, 0, nil
	self.hold_pending, self.flush_pending = false, false
	self.pause_reasons = ACTIVE[phase] and kept_reasons(self, old) or {}

	if phase == "running" then
		self.co = create(run_body)
		self.wait_until_s = number_or(old.wait_until_s, nil) -- wait_left() until the replay
		if position.steps_begun == 0 then
			arrive(self, position) -- before the first step: nothing to replay
		else
			self.replay = position
		end
	elseif phase == "cancelling" then
		stop(self) -- the cleanup again from its start, from safe outputs
	elseif FINISHED[phase] then
		-- the last outputs of a cycle that ended after its last tick
		self.hold_pending = old.hold_pending == true
		self.flush_pending = old.flush_pending == true
	end
	update_state(self)
	return true
end

return cycle
