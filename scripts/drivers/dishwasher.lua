-- Dishwasher: fill until the level switch, wash for a set time, drain, and
-- again for each rinse (docs/BOARD.md, "Dishwasher"). Programmes are files
-- in scripts/cycles/dishwasher/, written with the steps this driver offers
-- (`d` below): fill, wash, drain, dry. The door has no lock: opening it
-- stops everything and pauses the programme until it is closed again. A
-- hot reload continues a running programme where it was (migrate, below);
-- after a restart, recover resumes it from the host's checkpoint when that
-- is fresh and the plant agrees, else cancels it (drains).

local appliance = require "appliance"
local cycle = require "cycle"
local interlock = require "interlock"

local programs = vmac.cycles() -- scripts/cycles/dishwasher/*.lua: name -> function(d)
local program_names = {}
for name in pairs(programs) do
	program_names[#program_names + 1] = name
end
table.sort(program_names)

local IDLE_LEVEL, RUN_LEVEL = 6, 5
-- Recovery: the water may differ this much from the checkpoint's. Nothing
-- moves the water while the outputs are off; a fill (3 l at 0.25 l/s) may
-- have gone on for a periodic checkpoint's 5 s after it; drained is 3 l less.
local RECOVER_LEVEL_L = 1.5

local driver = {
	name = "dishwasher",
	version = "1.2.0",
	level = IDLE_LEVEL,
	description = "dishwasher: fill to the level switch, wash, drain, rinse; door interlock",
	io = {
		fill_valve = "do0",
		wash_motor = "do1",
		drain_pump = "do2",
		door_closed = "di0",
		level_switch = "di1",
		start_button = "di2",
		cancel_button = "di3",
		level_l = { "ai0", scale = 0.01, unit = "l" },
	},
	params = {
		program = { default = "normal", values = program_names, persist = true, label = "Programme" },
		time_scale = { default = 1, min = 0.001, max = 10, step = 0.001, label = "Time scale (tests and demos)",
		               enabled_by_default = false },
		fill_timeout_s = { default = 120, min = 5, max = 3600, unit = "s", label = "Longest fill" },
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
		level_l = { unit = "l", update = "timer:0.5", label = "Water" },
		door = { label = "Door", values = { "open", "closed" }, device_class = "enum" },
	},
	commands = {
		start = { label = "Start", arg = "program" },
		pause = { label = "Pause" },
		resume = { label = "Resume" },
		cancel = { label = "Cancel" },
	},
	ui = { title = "Dishwasher", icon = "dishwasher", plots = { { "level_l" } } },
}

local want = { fill_valve = false, wash_motor = false, drain_pump = false }
local params
-- The last water level, kept in dev.state for the recovery check.
local last = { level_l = nil }
-- Set by recover when a programme resumes: what the first tick checks the
-- plant against ({level_l = }), then nil.
local recovery = nil

local function all_off(o)
	o.fill_valve, o.wash_motor, o.drain_pump = false, false, false
end

local door = interlock.new {
	name = "door open",
	trip = function(i) return not i.door_closed end,
	safe = all_off,
}

local function steps_for(c)
	local d = {}
	local function scaled(minutes) return minutes * 60 * params.time_scale end
	function d.fill()
		c:step("fill", function()
			c.out.fill_valve = true
			c:wait_until(function() return c.inp.level_switch end, params.fill_timeout_s, "the level switch")
			c.out.fill_valve = false
		end)
	end
	function d.wash(spec)
		c:step(spec.name or "wash", function()
			c.out.wash_motor = true
			c:wait(scaled(spec.minutes or 20))
			c.out.wash_motor = false
		end)
	end
	function d.drain()
		c:step("drain", function()
			c.out.drain_pump = true
			c:wait_until(function() return c.inp.level_l < 0.05 end, 120, "an empty tank")
			c.out.drain_pump = false
		end)
	end
	function d.dry(spec)
		c:step("dry", function() c:wait(scaled(spec.minutes or 10)) end)
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
	cleanup = function(c) steps_for(c).drain() end,
})

control = appliance.new { cycle = run, programs = programs, idle_level = IDLE_LEVEL, run_level = RUN_LEVEL }

function driver.attach(dev)
	params = dev.params
	dev.state.control = control -- the programme, the buttons and the cycle (migrate, recover)
	dev.state.last = last
end

-- The first tick after recover resumed a programme: the door closed and
-- the water within RECOVER_LEVEL_L of the checkpoint's, or it is cancelled
-- (drained), saying why.
local function check_plant(dev, inputs, r)
	local why
	if not inputs.door_closed then
		why = "the door is open"
	elseif type(r.level_l) ~= "number" then
		why = "the checkpoint has no water level to compare"
	elseif math.abs(inputs.level_l - r.level_l) > RECOVER_LEVEL_L then
		why = string.format("the water level is %.1f l, the checkpoint had %.1f l", inputs.level_l, r.level_l)
	end
	control:agree(dev, why)
end

function driver.tick(dev, inputs)
	if recovery then
		check_plant(dev, inputs, recovery)
		recovery = nil
	end
	last.level_l = inputs.level_l
	control:buttons(dev, inputs.start_button, inputs.cancel_button)
	run:tick(inputs.time, inputs, want)
	control:publish(dev)
	dev.out.fill_valve, dev.out.wash_motor, dev.out.drain_pump = want.fill_valve, want.wash_motor, want.drain_pump

	local v = dev.vars
	v.level_l = inputs.level_l
	v.door = inputs.door_closed and "closed" or "open"
end

function driver.input(dev, name, value)
	return control:input(dev, name, value)
end

-- Hot reload (docs/DRIVERS.md): after attach, with the old version's
-- outputs in dev.out. The programme goes on where it was.
function driver.migrate(dev, old)
	if type(old.control) ~= "table" then -- 1.0.0 kept nothing in dev.state
		local out = dev.out
		if out.fill_valve or out.wash_motor or out.drain_pump then
			error("the running version keeps no state to continue from; reload when the dishwasher is idle", 0)
		end
		return
	end
	assert(control:restore(old.control))
end

-- Recovery after a restart (docs/DRIVERS.md), after attach and before the
-- first tick, with the host's last checkpoint of dev.state: a running (or
-- paused) programme resumes where it was when the checkpoint is at most
-- recover_max_age_s old and the plant agrees at the first tick
-- (check_plant); older, it is cancelled at once. One that was cancelling
-- goes on draining. Idle or finished: nothing to resume (a finished
-- programme's status is kept). The cycle goes on from os.clock(): the bus
-- clock started again.
function driver.recover(dev, saved)
	local old = saved.state
	if type(old) ~= "table" then
		return
	end
	if control:recover(dev, old.control, saved.age_s, params.recover_max_age_s) == "resume" then
		recovery = { level_l = type(old.last) == "table" and old.last.level_l or nil }
	end
end

return driver
