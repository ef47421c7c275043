-- dryer.lua: a tumble dryer, written as user content beside the shipped
-- drivers (docs/NEW_MACHINE.md makes it from an empty folder). Programmes
-- are files in cycles/dryer/, written with the steps this driver offers
-- (`d` below): dry (warm up to a temperature, then hold it while the drum
-- tumbles) and cool (tumble without heat). The heater follows a PID loop
-- on the air temperature, as a duty cycle over a few seconds. Safety: the
-- door interlock turns the heater and the drum off as soon as the driver
-- sees the door open, and the programme goes on when it is closed again;
-- the heater is on only while the drum's rotation sensor says it turns.
-- Instant safety is in the wiring (plants/dryer.lua): an open door powers
-- neither, and a thermal cut-out opens the heater's supply when too hot.

local appliance = require "appliance"
local cycle = require "cycle"
local interlock = require "interlock"
local pid = require "pid"

local programs = vmac.cycles() -- cycles/dryer/*.lua: name -> function(d)
local program_names = {}
for name in pairs(programs) do
	program_names[#program_names + 1] = name
end
table.sort(program_names)

-- 64 ms idle, 32 ms running (1 ms slots): the air warms over minutes, and
-- the door interlock answers within two periods (NEW_MACHINE.md says why).
local IDLE_LEVEL, RUN_LEVEL = 6, 5
local HEAT_WINDOW_S = 5  -- the heater's duty cycle is spread over this
local DRUM_START_S = 5   -- the longest the drum may take to turn
local WARM_BAND_C = 2    -- warm up ends this close to the target
local SAFE_C = 45        -- a cancelled programme tumbles the laundry below this

local driver = {
	name = "dryer",
	version = "1.0.0",
	level = IDLE_LEVEL,
	description = "tumble dryer: warm up, dry at a temperature, cool down; door interlock",
	io = {
		heater = "do0",
		drum = "do1",
		door_closed = "di0",
		start_button = "di1",
		cancel_button = "di2",
		drum_turning = "di3",
		temp_c = { "ai0", scale = 0.05, offset = -20, unit = "degC" },
	},
	params = {
		program = { default = "cotton", values = program_names, persist = true, label = "Programme" },
		time_scale = { default = 1, min = 0.001, max = 10, step = 0.001, label = "Time scale (tests and demos)",
		               enabled_by_default = false },
		heat_timeout_s = { default = 900, min = 60, max = 3600, unit = "s", label = "Longest warm-up" },
		recover_max_age_s = { default = 600, min = 0, max = 86400, unit = "s",
		                      label = "Oldest checkpoint a programme resumes from" },
	},
	variables = {
		state = { group = "cycle", label = "State", device_class = "enum",
		          values = { "idle", "running", "paused", "cancelling", "done", "failed", "cancelled" } },
		cycle = { group = "cycle", label = "Programme running" },
		step = { group = "cycle", label = "Step" },
		running = { group = "cycle", device_class = "running" },
		paused_by = { group = "cycle", label = "Paused by", entity_category = "diagnostic" },
		error = { group = "cycle", label = "Error" },
		time_left_s = { unit = "s", update = "timer:1", label = "Time left in step" },
		temp_c = { unit = "degC", update = "timer:1", label = "Temperature", device_class = "temperature",
		           precision = 1 },
		target_c = { unit = "degC", label = "Target temperature", precision = 0 },
		heater = { label = "Heater", device_class = "heat" },
		drum = { label = "Drum turning", device_class = "moving" },
		door_open = { label = "Door open", device_class = "door" },
	},
	commands = {
		start = { label = "Start", arg = "program" },
		pause = { label = "Pause" },
		resume = { label = "Resume" },
		cancel = { label = "Cancel" },
	},
	ui = { title = "Dryer", icon = "dryer", plots = { { "temp_c", "target_c" }, { "heater", "drum" } } },
}

-- What the steps ask for: the drum, and the air temperature to hold (0: no heat).
local want = { drum = false, target_c = 0 }
local params -- dev.params, for the steps
-- The heater's loop: duty 0..1 from the temperature error.
local temp_loop = pid.new { kp = 0.15, ki = 0.002, out_min = 0, out_max = 1 }
-- What tick() carries over: the last bus time, the door at the last tick
-- (for a start between ticks), and since when the drum should turn but does
-- not (nil: it turns, or should not).
local memory = { time = nil, door_closed = false, stalled_since = nil }
local recovering = false -- recover resumed a programme: the first tick checks the door

local function all_off(o)
	o.drum, o.target_c = false, 0
end

local door = interlock.new {
	name = "door open",
	trip = function(i) return not i.door_closed end,
	safe = all_off,
}

-- The steps a programme is written with: d.dry{temp_c = , minutes = }, d.cool{minutes = }.
local function steps_for(c)
	local d = {}
	local function scaled(minutes) return minutes * 60 * params.time_scale end
	local function start_drum()
		c.out.drum = true
		c:wait_until(function() return c.inp.drum_turning end, DRUM_START_S, "the drum to turn")
	end
	function d.dry(spec)
		local target = assert(tonumber(spec.temp_c), "dry: temp_c must be a number")
		c:step("warm up", function()
			start_drum()
			c.out.target_c = target
			c:wait_until(function() return c.inp.temp_c >= target - WARM_BAND_C end, params.heat_timeout_s,
				target .. " C")
		end)
		c:step("dry", function()
			start_drum()
			c.out.target_c = target
			c:wait(scaled(spec.minutes or 40))
		end)
	end
	function d.cool(spec)
		c:step("cool", function()
			c.out.target_c = 0
			start_drum()
			c:wait(scaled(spec.minutes or 10))
			c.out.drum = false
		end)
	end
	return d
end

local control -- the appliance: programmes, buttons, commands (below)

local run = cycle.new(function(c)
	control:programme()(steps_for(c))
end, {
	interlocks = { door },
	outputs = want,
	hold = all_off,
	cleanup = function(c) -- after cancel or a failure: no heat; tumble hot laundry cool
		c:step("cool", function()
			c.out.target_c = 0
			if c.inp.temp_c > SAFE_C then
				c.out.drum = true
				c:try_wait_until(function() return c.inp.temp_c <= SAFE_C end, 900)
			end
			c.out.drum = false
		end)
	end,
})

control = appliance.new {
	cycle = run,
	programs = programs,
	idle_level = IDLE_LEVEL,
	run_level = RUN_LEVEL,
	can_start = function()
		if not memory.door_closed then return "close the door first" end
	end,
}

-- The heater: the loop's duty as a share of each HEAT_WINDOW_S, and only
-- while the drum is sensed turning (a still drum scorches the laundry).
local function heater_on(inputs, dt)
	if want.target_c <= 0 or not want.drum then
		temp_loop:reset()
		return false
	end
	local duty = temp_loop:update(want.target_c, inputs.temp_c, dt)
	return inputs.drum_turning and inputs.time % HEAT_WINDOW_S < duty * HEAT_WINDOW_S
end

-- A drum that does not turn with its motor on (a broken belt) cancels the
-- programme, saying why; the heater is off already (heater_on).
local function watch_drum(dev, inputs)
	if not (run.phase == "running" and run.state == "running" and want.drum) or inputs.drum_turning then
		memory.stalled_since = nil
	elseif not memory.stalled_since then
		memory.stalled_since = inputs.time
	elseif inputs.time - memory.stalled_since > DRUM_START_S then
		memory.stalled_since = nil
		dev:event("the drum does not turn with its motor on (a broken belt?): programme cancelled")
		run:cancel()
	end
end

function driver.attach(dev)
	params = dev.params
	dev.state.control = control -- the programme, the buttons and the cycle
	dev.state.temp_loop, dev.state.memory = temp_loop, memory
end

function driver.tick(dev, inputs)
	local dt = memory.time and inputs.time - memory.time or 0
	memory.time, memory.door_closed = inputs.time, inputs.door_closed
	if recovering then
		recovering = false
		control:agree(dev, not inputs.door_closed and "the door is open" or nil)
	end
	control:buttons(dev, inputs.start_button, inputs.cancel_button)
	run:tick(inputs.time, inputs, want)
	watch_drum(dev, inputs)
	control:publish(dev)

	local o = dev.out
	o.drum = want.drum
	o.heater = heater_on(inputs, dt)

	local v = dev.vars
	v.temp_c, v.target_c = inputs.temp_c, want.target_c
	v.heater, v.drum, v.door_open = o.heater, inputs.drum_turning, not inputs.door_closed
end

function driver.input(dev, name, value)
	return control:input(dev, name, value)
end

function driver.detach()
	all_off(want)
end

-- Hot reload (docs/DRIVERS.md): the programme goes on where it was, the
-- heater's loop from its last values.
function driver.migrate(dev, old)
	if type(old.control) == "table" then
		assert(control:restore(old.control))
	end
	if type(old.temp_loop) == "table" then
		for _, k in ipairs { "i_term", "p_term", "d_term", "output" } do
			if type(old.temp_loop[k]) == "number" then temp_loop[k] = old.temp_loop[k] end
		end
	end
end

-- Recovery after a restart: a programme resumes from a checkpoint at most
-- recover_max_age_s old when the door is closed at the first tick (the
-- outputs went off while the host was away: it warms up again as needed);
-- otherwise it is cancelled (no heat, tumbled cool).
function driver.recover(dev, saved)
	local old = saved.state
	if type(old) == "table" and
		control:recover(dev, old.control, saved.age_s, params.recover_max_age_s) == "resume" then
		recovering = true
	end
end

return driver
