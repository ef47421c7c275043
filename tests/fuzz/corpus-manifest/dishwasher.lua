-- Dishwasher: fill until the level switch, wash for a set time, drain, and
-- again for each rinse (docs/BOARD.md, "Dishwasher"). Programmes are files
-- in scripts/cycles/dishwasher/, written with the steps this driver offers
-- (`d` below): fill, wash, drain, dry. The door has no lock: opening it
-- stops everything and pauses the programme until it is closed again. A
-- hot reload continues a running programme where it was (migrate, below).

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

local driver = {
	name = "dishwasher",
	version = "1.1.0",
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
		time_scale = { default = 1, min = 0.001, max = 10, label = "Time scale (tests and demos)" },
		fill_timeout_s = { default = 120, min = 5, max = 3600, unit = "s", label = "Longest fill" },
	},
	variables = {
		state = { group = "cycle", label = "State" },
		cycle = { group = "cycle", label = "Programme running" },
		step = { group = "cycle", label = "Step" },
		running = { group = "cycle" },
		paused_by = { group = "cycle", label = "Paused by" },
		error = { group = "cycle", label = "Error" },
		time_left_s = { unit = "s", update = "timer:1", label = "Time left in step" },
		level_l = { unit = "l", update = "timer:0.5", label = "Water" },
		door = { label = "Door" },
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
	dev.state.control = control -- the programme, the buttons and the cycle (migrate)
end

function driver.tick(dev, inputs)
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

return driver
