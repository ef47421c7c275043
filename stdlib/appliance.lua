-- appliance: the operator's side of an appliance that runs programmes
-- (docs/STDLIB.md "appliance"): start a programme by name, pause, resume and
-- cancel, the machine's start and cancel buttons, a faster service level
-- while a programme runs, and the programme's status as published variables.
-- The programme itself is a `cycle`; the driver keeps its outputs and its
-- safety (interlocks, guards). publish() asks the host for a checkpoint of
-- dev.state at every change of the programme's state or step; restore()
-- continues the appliance of the old instance of the driver after a hot
-- reload, or of a checkpoint after a restart.

local type, error, tostring = type, error, tostring

local appliance = {}

local Appliance = {}
Appliance.__index = Appliance

-- appliance.new{cycle = , programs = , idle_level = , run_level = , can_start = ?}
--   cycle: the cycle.new object that runs the chosen programme
--   programs: name -> programme (what vmac.cycles() returned)
--   idle_level, run_level: service levels when idle and while running
--   can_start(): nil to allow a start, or a message saying why not
function appliance.new(spec)
	if type(spec) ~= "table" then
		error("appliance.new: expects a table {cycle=, programs=, idle_level=, run_level=}", 2)
	end
	if type(spec.cycle) ~= "table" or type(spec.cycle.start) ~= "function" then
		error("appliance.new: cycle must be a cycle (cycle.new)", 2)
	end
	if type(spec.programs) ~= "table" then
		error("appliance.new: programs must be a table name -> programme", 2)
	end
	for _, k in ipairs({ "idle_level", "run_level" }) do
		local v = spec[k]
		if type(v) ~= "number" or v ~= v or v < 0 or v % 1 ~= 0 then
			error("appliance.new: " .. k .. " must be a whole number >= 0", 2)
		end
	end
	if spec.can_start ~= nil and type(spec.can_start) ~= "function" then
		error("appliance.new: can_start must be a function returning nil or a message", 2)
	end
	return setmetatable({
		cycle = spec.cycle, programs = spec.programs,
		idle_level = spec.idle_level, run_level = spec.run_level, can_start = spec.can_start,
		chosen = nil,          -- name of the programme started last
		last_start = false,    -- button states at the previous tick: a button
		last_cancel = false,   -- held as the machine attaches counts as a press
		was_active = false,
		published_state = nil, -- state and step at the last publish: a change
		published_step = nil,  -- asks for a checkpoint (nil: none published yet)
		level_pending = false, -- restore(old, now): ask for run_level at the next publish
	}, Appliance)
end

-- Start programme `name` (nil: dev.params.program). Returns true, or nil and
-- a message for the operator (no such programme, can_start's reason, or the
-- cycle's own refusal: "cycle is already running").
function Appliance:start(dev, name)
	name = name or dev.params.program
	if self.programs[name] == nil then
		return nil, "no programme '" .. tostring(name) .. "'"
	end
	local why = self.can_start and self.can_start()
	if why then
		return nil, why
	end
	-- The cycle's body asks programme() at its first tick, after this; a
	-- refused start leaves the running programme's name alone.
	local ok, err = self.cycle:start()
	if ok then
		self.chosen = name
		dev:set_level(self.run_level)
		dev.vars.cycle = name
	end
	return ok, err
end

-- The programme chosen by the last start (for the cycle's body).
function Appliance:programme()
	return self.programs[self.chosen]
end

-- Once per tick, before the cycle's tick: rising edges of the buttons.
function Appliance:buttons(dev, start_pressed, cancel_pressed)
	if start_pressed and not self.last_start then
		self:start(dev)
	end
	if cancel_pressed and not self.last_cancel then
		self.cycle:cancel()
	end
	self.last_start, self.last_cancel = start_pressed == true, cancel_pressed == true
end

-- Once per tick, after the cycle's tick: back to the idle level when the
-- programme has ended (to the running level after a recovery), and the
-- status variables (cycle, state, step, running, paused_by, error,
-- time_left_s). At the first publish and whenever the state or the step
-- changed since the last one, dev:checkpoint(), so the host's checkpoint
-- says where the programme is (a host without checkpoints: nothing).
function Appliance:publish(dev)
	local c, v = self.cycle, dev.vars
	local active = c:active()
	if self.level_pending then
		self.level_pending = false
		if active then dev:set_level(self.run_level) end
	end
	if self.was_active and not active then
		dev:set_level(self.idle_level)
	end
	self.was_active = active
	v.cycle = self.chosen
	v.state, v.step, v.running = c.state, c.step_name or "-", active
	v.paused_by, v.error = c.pause_reasons[1] or "", c.error or ""
	v.time_left_s = c:wait_left() or 0
	if v.state ~= self.published_state or v.step ~= self.published_step then
		self.published_state, self.published_step = v.state, v.step
		if dev.checkpoint then dev:checkpoint() end
	end
end

-- The operator commands start (value: a programme name, or true for the
-- default), pause, resume and cancel, as the driver's input() returns them:
-- true, or nil and a message. Any other name is taken as accepted (true):
-- the host has already set a param in dev.params; a driver with commands of
-- its own handles them before calling this.
function Appliance:input(dev, name, value)
	if name == "start" then
		return self:start(dev, value ~= true and value or nil)
	elseif name == "pause" then
		return self.cycle:pause()
	elseif name == "resume" then
		return self.cycle:resume()
	elseif name == "cancel" then
		return self.cycle:cancel()
	end
	return true
end

-- Take over the appliance of the old instance of the driver (hot reload):
-- old is the plain-data copy of it found in migrate's old_state. Keeps the
-- programme chosen last, the buttons' states at the old instance's last
-- tick (a button held across the reload is no new press), whether a
-- programme was running (so the idle level comes back when it ends), and the
-- cycle (cycle:restore). now (optional): recovery from a checkpoint after a
-- restart (docs/STDLIB.md "Recovery"): the bus time to go on from, passed to
-- cycle:restore; the buttons start afresh (held at the first tick is a
-- press, as at any attach), and the next publish asks for run_level while
-- the programme is active (the machine attached at its idle level).
-- Returns true, or nil and a message when the programme cannot go on: the
-- running one is not among this version's programmes, or the cycle's own
-- refusal. Nothing is changed then.
function Appliance:restore(old, now)
	if type(old) ~= "table" or type(old.cycle) ~= "table" then
		error("appliance:restore: old must be a copy of an appliance (a table with its cycle)", 2)
	end
	if now ~= nil and (type(now) ~= "number" or now ~= now) then
		error("appliance:restore: now must be a number (bus time, seconds) or nil", 2)
	end
	local chosen = old.chosen
	if type(chosen) ~= "string" then
		chosen = nil
	end
	if old.cycle.phase == "running" and self.programs[chosen] == nil then
		return nil, "appliance:restore: programme '" .. tostring(chosen)
			.. "' is running, but this version has no programme of that name"
	end
	local ok, err = self.cycle:restore(old.cycle, now)
	if not ok then
		return nil, err
	end
	self.chosen = chosen
	if now == nil then
		self.last_start, self.last_cancel = old.last_start == true, old.last_cancel == true
	else
		self.last_start, self.last_cancel = false, false
		self.level_pending = true
	end
	self.was_active = old.was_active == true
	return true
end

-- ---- recovery after a restart (docs/DRIVERS.md "Recovery after a restart") ----

local ENDED = { done = true, cancelled = true, failed = true }

local function where(self)
	return tostring(self.chosen) .. " at step " .. tostring(self.cycle.step_name)
end

local function age_text(age_s)
	if age_s == math.huge then -- no age, or the host's clock now before the checkpoint's
		return "checkpoint of unknown age"
	end
	return string.format("checkpoint %.0f s old", age_s)
end

-- In the driver's recover(dev, saved): take over the appliance of the
-- checkpoint, old (the plain copy of it in saved.state), age_s old, with the
-- bus clock that started again (os.clock()). Returns what became of it:
--   "idle"       nothing was running: nothing taken over
--   "ended"      a finished programme: its status taken over
--   "cancelling" a cancel was under way: its cleanup starts again
--   "cancelled"  the programme could not go on (older than max_age_s, or its
--                programme is not in this version): cancelled, so its
--                cleanup runs; an event says why
--   "resume"     the programme goes on where it was: check the plant at the
--                first tick and call self:agree(dev, why) with what is wrong
--                (nil when nothing is)
function Appliance:recover(dev, old, age_s, max_age_s)
	if type(old) ~= "table" or type(old.cycle) ~= "table" then
		return "idle"
	end
	local phase = old.cycle.phase
	local active = phase == "running" or phase == "cancelling"
	if not active and not ENDED[phase] then
		return "idle"
	end
	age_s = tonumber(age_s) or math.huge -- no age: too old to trust
	self.recover_age_s = age_s
	local ok, err = self:restore(old, os.clock())
	if not ok then -- e.g. its programme is gone: make the machine safe instead
		local copy = {}
		for k, v in pairs(old) do copy[k] = v end
		copy.cycle = {}
		for k, v in pairs(old.cycle) do copy.cycle[k] = v end
		copy.cycle.phase = "cancelling"
		assert(self:restore(copy, os.clock()))
		dev:event("recovery: cannot resume (" .. err .. "): cancelling")
		return "cancelled"
	end
	if not active then
		return "ended"
	elseif phase == "cancelling" then
		dev:event("recovered: cancelling " .. tostring(self.chosen) .. " goes on (" .. age_text(age_s) .. ")")
		return "cancelling"
	elseif age_s > max_age_s then
		dev:event(string.format("recovery: %s, more than %g s: cancelling %s", age_text(age_s), max_age_s,
			where(self)))
		self.cycle:cancel()
		return "cancelled"
	end
	return "resume"
end

-- At the first tick after recover returned "resume": why is what the
-- plant says against going on (nil: nothing): the programme is cancelled
-- then, else it resumes; an event says which, and why.
function Appliance:agree(dev, why)
	local age = age_text(self.recover_age_s or 0)
	if why then
		dev:event("recovery: " .. why .. ": cancelling " .. where(self) .. " (" .. age .. ")")
		self.cycle:cancel()
	else
		dev:event("recovered: resuming " .. where(self) .. " (" .. age .. ")")
	end
end

return appliance
