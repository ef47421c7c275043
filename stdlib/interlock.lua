-- interlock: a safety condition for drivers (docs/STDLIB.md "interlock").
-- While it trips (e.g. the washer door is open) it holds: safe(outputs)
-- every tick, and a guarded cycle pauses. When it clears, an optional re-arm
-- action runs until it reports done (e.g. lock the door until the lock
-- input confirms), and only then does the cycle resume.
-- Time comes only from the caller (bus time in seconds).

local type, error = type, error

local interlock = {}

local Interlock = {}
Interlock.__index = Interlock

-- interlock.new{name=, trip=, safe=, rearm=?, rearm_timeout=?} -> an
-- interlock in state "clear".
--   trip(inputs, il) -> true while unsafe
--   safe(outputs, inputs, il): make the outputs safe (every tick it holds)
--   rearm(outputs, inputs, il) -> true when re-armed (every tick after the
--     trip cleared, after safe, until it returns true)
--   rearm_timeout: seconds of bus time re-arming may take before the
--     interlock goes to "fault" (holds until it trips and clears again)
function interlock.new(spec)
	if type(spec) ~= "table" then
		error("interlock.new: expects a table {name=, trip=, safe=, rearm=?}", 2)
	end
	local name = spec.name
	if type(name) ~= "string" or name == "" then
		error("interlock.new: name must be a non-empty string (shown as the pause reason)", 2)
	end
	if type(spec.trip) ~= "function" then
		error("interlock.new: trip must be a function(inputs) returning true while unsafe", 2)
	end
	if type(spec.safe) ~= "function" then
		error("interlock.new: safe must be a function(outputs, inputs) that makes the outputs safe", 2)
	end
	if spec.rearm ~= nil and type(spec.rearm) ~= "function" then
		error("interlock.new: rearm must be a function(outputs, inputs) returning true when re-armed", 2)
	end
	local timeout = spec.rearm_timeout
	if timeout ~= nil then
		if type(timeout) ~= "number" or timeout ~= timeout or timeout <= 0 then
			error("interlock.new: rearm_timeout must be a number > 0 (seconds)", 2)
		end
		if spec.rearm == nil then
			error("interlock.new: rearm_timeout needs a rearm function", 2)
		end
	end
	return setmetatable({
		name = name, trip = spec.trip, safe = spec.safe, rearm = spec.rearm,
		rearm_timeout = timeout,
		state = "clear", -- "clear", "tripped", "rearming" or "fault"
		since = nil,     -- bus time of the last change of state
		message = nil,   -- why it is in "fault"
		rearmed = false, -- rearm() returned true at the last apply()
	}, Interlock)
end

local function enter(il, state, now)
	il.state, il.since = state, now
end

-- Back to "clear", e.g. when a cycle starts.
function Interlock:reset()
	self.state, self.since, self.message, self.rearmed = "clear", nil, nil, false
end

local STATES = { clear = true, tripped = true, rearming = true, fault = true }

-- Take over the state of the same interlock in another instance of the
-- driver (hot reload): old is a plain copy of it, its functions dropped.
-- One that held goes on holding, so a door being locked again must still
-- report locked before a guarded cycle goes on. now (optional): the bus
-- time of a new clock (recovery after a restart, where the old bus time
-- means nothing): the state counts as entered at now, so a re-arm gets its
-- whole rearm_timeout again.
function Interlock:restore(old, now)
	if type(old) ~= "table" or not STATES[old.state] then
		error("interlock:restore: old must be a copy of an interlock (a table with its state)", 2)
	end
	if now ~= nil and (type(now) ~= "number" or now ~= now) then
		error("interlock:restore: now must be a number (bus time, seconds) or nil", 2)
	end
	self.state = old.state
	if now ~= nil then
		self.since = now
	else
		self.since = type(old.since) == "number" and old.since or nil
	end
	self.message = type(old.message) == "string" and old.message or nil
	self.rearmed = old.rearmed == true
end

-- level 3: the caller of the public function that checks.
local function check_time_inputs(now, inputs, where)
	if type(now) ~= "number" or now ~= now then
		error(where .. ": now must be a number (bus time, seconds)", 3)
	end
	if type(inputs) ~= "table" then
		error(where .. ": inputs must be a table", 3)
	end
end

local function update(self, now, inputs)
	local state = self.state
	if self.trip(inputs, self) then
		if state ~= "tripped" then
			enter(self, "tripped", now)
			self.message = nil
		end
	elseif state == "tripped" then
		self.rearmed = false
		enter(self, self.rearm and "rearming" or "clear", now)
	elseif state == "rearming" then
		if self.rearmed then
			enter(self, "clear", now)
		elseif self.rearm_timeout and now - self.since >= self.rearm_timeout then
			enter(self, "fault", now)
			self.message = self.name .. ": not re-armed within " .. self.rearm_timeout .. " s"
		end
	end
	return self.state ~= "clear"
end

-- Evaluate the condition on this tick's inputs and advance the state.
-- Returns true while the interlock holds (any state but "clear").
function Interlock:update(now, inputs)
	check_time_inputs(now, inputs, "interlock:update")
	return update(self, now, inputs)
end

-- Write this tick's outputs: safe() while tripped or in fault; safe() and
-- then rearm() while re-arming. Nothing while clear.
local function apply(self, outputs, inputs)
	local state = self.state
	if state == "clear" then
		return
	end
	self.safe(outputs, inputs, self)
	if state == "rearming" then
		self.rearmed = self.rearm(outputs, inputs, self) and true or false
	end
end

function Interlock:apply(outputs, inputs)
	if type(outputs) ~= "table" then
		error("interlock:apply: outputs must be a table", 2)
	end
	apply(self, outputs, inputs)
end

-- update() and apply() in one call, for a driver without a cycle.
-- Returns true while the interlock holds.
function Interlock:tick(now, inputs, outputs)
	check_time_inputs(now, inputs, "interlock:tick")
	if type(outputs) ~= "table" then
		error("interlock:tick: outputs must be a table", 2)
	end
	local holding = update(self, now, inputs)
	apply(self, outputs, inputs)
	return holding
end

return interlock
