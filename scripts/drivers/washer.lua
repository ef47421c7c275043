-- Washer: the thesis washer (chapter 6.6) on the generic board with the
-- washer plant (docs/BOARD.md, "Washer"). Programmes are separate files in
-- scripts/cycles/washer/, written with the steps this driver offers (`w`
-- below): lock, fill, wash, drain, spin, unlock. The drum runs on a PID
-- velocity loop behind a ramp; the door interlock stops everything when the
-- door opens and resumes after it is closed and locked again; cancel stops
-- the drum and drains. The door is never unlocked while the drum turns or
-- the water is above the door. A hot reload continues a running programme
-- where it was (dev.state and migrate, at the end); after a restart, recover
-- resumes it from the host's checkpoint when that is fresh and the plant
-- agrees, else cancels it (drains and unlocks).

local appliance = require "appliance"
local cycle = require "cycle"
local interlock = require "interlock"
local pid = require "pid"
local ramp = require "ramp"

local programs = vmac.cycles() -- scripts/cycles/washer/*.lua: name -> function(w)
local program_names = {}
for name in pairs(programs) do
	program_names[#program_names + 1] = name
end
table.sort(program_names)

-- 32 ms idle, 16 ms running (with 1 ms slots): the drum's time constant is
-- over a second (docs/BOARD.md), so its loop needs no faster service.
local IDLE_LEVEL, RUN_LEVEL = 5, 4
local COUNTS_PER_REV = 360
local STILL_RPM = 2 -- below this the drum counts as stopped
local TEMPS = { hot = { true, false }, warm = { true, true }, cold = { false, true } }
local RECOVER_LEVEL_L = 2 -- recovery: the water may differ this much from the checkpoint's

local driver = {
	name = "washer",
	version = "1.2.0",
	level = IDLE_LEVEL,
	description = "washing machine: fill, wash, rinse, spin; door interlock",
	io = {
		hot_valve = "do0",
		cold_valve = "do1",
		drain_pump = "do2",
		door_lock = "do3",
		motor_on = "do4",
		drum_drive = "pwm",
		door_closed = "di0",
		door_locked = "di1",
		tub_empty = "di2",
		start_button = "di3",
		cancel_button = "di4",
		level_l = { "ai0", scale = 0.01, unit = "l" },
		temp_c = { "ai1", scale = 0.025, unit = "degC" },
		drum = "encoder",
	},
	params = {
		program = { default = "normal", values = program_names, persist = true, label = "Programme" },
		time_scale = { default = 1, min = 0.001, max = 10, step = 0.001, label = "Time scale (tests and demos)",
		               enabled_by_default = false },
		door_level_l = { default = 5, min = 0, max = 40, unit = "l", label = "Water level of the door" },
		fill_timeout_s = { default = 300, min = 10, max = 3600, unit = "s", label = "Longest fill" },
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
		drum_rpm = { unit = "rpm", update = "timer:0.2", label = "Drum" },
		drum_setpoint_rpm = { unit = "rpm", update = "timer:0.2", label = "Drum set point", precision = 0,
		                      entity_category = "diagnostic" },
		level_l = { unit = "l", update = "timer:0.5", label = "Water" },
		temp_c = { unit = "degC", update = "timer:1", label = "Temperature", device_class = "temperature",
		           precision = 1 },
		door = { label = "Door", values = { "open", "closed", "locked" }, device_class = "enum" },
	},
	commands = {
		start = { label = "Start", arg = "program" },
		pause = { label = "Pause" },
		resume = { label = "Resume" },
		cancel = { label = "Cancel" },
	},
	ui = {
		title = "Washer",
		icon = "washer",
		plots = { { "drum_rpm", "drum_setpoint_rpm" }, { "level_l" } },
	},
}

-- What the cycle and the interlock ask for; mapped to the board each tick.
local want = { hot_valve = false, cold_valve = false, drain_pump = false, door_lock = false,
	motor_on = false, motor_rpm = 0 }
-- Named inputs plus the measured drum speed, for the steps.
local inp = { drum_rpm = 0 }
-- What the driver carries from tick to tick besides the cycle: the last
-- encoder reading and its bus time (for the drum speed), whether the drum
-- speed has been measured yet (not on the first tick of a new instance),
-- whether the guard holds the door locked, and the drum's set point.
local memory = { encoder = nil, time = nil, measured = false, guard = false, setpoint_rpm = 0 }
local params -- dev.params, for the steps
-- Set by recover when a programme resumes: what the first tick checks the
-- plant against ({level_l = }), then nil.
local recovery = nil

local function all_off(o)
	o.hot_valve, o.cold_valve, o.drain_pump = false, false, false
	o.motor_on, o.motor_rpm, o.door_lock = false, 0, false
end

local function safe_below(still_rpm)
	return math.abs(inp.drum_rpm) < still_rpm and (inp.level_l or 0) <= params.door_level_l
end

local function safe_to_open()
	return safe_below(STILL_RPM)
end

-- The guard: never unlock a closed door on a turning drum or on water above
-- it, whatever the cycle asks. It holds the lock from the moment it is
-- unsafe until the drum has clearly stopped (half the still speed), so a
-- drum coasting near the threshold cannot make the solenoid chatter, and
-- not before the drum speed has been measured (a recovered machine starts
-- with the guard of its checkpoint: the drum may still turn). A door
-- already open (the emergency release) is not locked: the interlock has
-- everything off.
local function guard_lock()
	if not inp.door_closed then
		memory.guard = false
	elseif not safe_to_open() then
		memory.guard = true
	elseif memory.guard and memory.measured and safe_below(STILL_RPM / 2) then
		memory.guard = false
	end
	return memory.guard
end

-- Paused: all off; the door stays locked until it is safe to open (the
-- guard in tick() holds it too).
local function hold(o)
	all_off(o)
	o.door_lock = not safe_to_open()
end

local door = interlock.new {
	name = "door open",
	trip = function(i) return not i.door_closed end,
	safe = all_off,
	rearm = function(o, i)
		o.door_lock = true
		return i.door_locked
	end,
	rearm_timeout = 5,
}

-- The steps a programme is written with: w.fill{temp = , litres = }, ...
local function steps_for(c)
	local w = {}
	local function scaled(minutes) return minutes * 60 * params.time_scale end
	local function stop_drum()
		c.out.motor_on, c.out.motor_rpm = true, 0 -- the ramp brakes it
		c:wait_until(function() -- (unknown before the first measurement: after a restart it may turn)
			return memory.measured and math.abs(c.inp.drum_rpm) < STILL_RPM
		end, 120, "the drum to stop")
		c.out.motor_on = false
	end
	function w.lock()
		c:step("lock", function()
			c.out.door_lock = true
			c:wait_until(function() return c.inp.door_locked end, 5, "the door lock")
		end)
	end
	function w.fill(spec)
		local valves = TEMPS[spec.temp or "cold"]
		assert(valves, "fill: temp must be hot, warm or cold")
		local litres = assert(tonumber(spec.litres), "fill: litres must be a number")
		c:step("fill", function()
			c.out.door_lock = true
			c.out.hot_valve, c.out.cold_valve = valves[1], valves[2]
			c:wait_until(function() return c.inp.level_l >= litres end, params.fill_timeout_s,
				litres .. " l of water")
			c.out.hot_valve, c.out.cold_valve = false, false
		end)
	end
	function w.wash(spec)
		c:step(spec.name or "wash", function()
			c.out.motor_on, c.out.motor_rpm = true, spec.rpm or 45
			c:wait(scaled(spec.minutes or 8))
			stop_drum()
		end)
	end
	function w.drain()
		c:step("drain", function()
			c.out.drain_pump = true
			c:wait_until(function() return c.inp.tub_empty end, 180, "an empty tub")
			c:wait(scaled(0.1)) -- the last of the water
			c.out.drain_pump = false
		end)
	end
	function w.spin(spec)
		c:step("spin", function()
			c.out.drain_pump = true
			c.out.motor_on, c.out.motor_rpm = true, spec.rpm or 400
			c:wait(scaled(spec.minutes or 5))
			stop_drum()
			c.out.drain_pump = false
		end)
	end
	function w.unlock()
		c:step("unlock", function()
			c:wait_until(safe_to_open, 120, "a still drum and the water below the door")
			c.out.door_lock = false
		end)
	end
	w.stop_drum = stop_drum
	return w
end

local control -- the appliance: programmes, buttons, commands (below)

local wash = cycle.new(function(c)
	local w = steps_for(c)
	w.lock()
	control:programme()(w)
	w.unlock()
end, {
	hold = hold,
	interlocks = { door },
	outputs = want,
	cleanup = function(c) -- after cancel or a failed step: stop, drain, unlock
		local w = steps_for(c)
		c.out.door_lock = true
		c:step("stop", w.stop_drum)
		w.drain()
		w.unlock()
	end,
})

-- The drum: a ramp shapes the requested speed, a PID follows it.
local drum_ramp = ramp.new { accel = 100, max_rate = 50 } -- RPM/s^2, RPM/s
local drum_pid = pid.new { kp = 2, ki = 0.8, out_min = -1000, out_max = 1000 }

local function drive_drum(dt)
	if not want.motor_on or not memory.measured then
		drum_pid:reset()
		drum_ramp:reset(inp.drum_rpm)
		memory.setpoint_rpm = 0
		return 0
	end
	local setpoint = drum_ramp:update(want.motor_rpm, dt)
	memory.setpoint_rpm = setpoint
	return drum_pid:update(setpoint, inp.drum_rpm, dt)
end

control = appliance.new {
	cycle = wash,
	programs = programs,
	idle_level = IDLE_LEVEL,
	run_level = RUN_LEVEL,
	can_start = function()
		if not inp.door_closed then return "close the door first" end
	end,
}

local function read_board(inputs)
	for k, v in pairs(inputs) do
		inp[k] = v
	end
	local dt = memory.time and inputs.time - memory.time or 0
	if dt > 0 then
		-- counts since the last tick, across the int32 wrap; 0.1 s filter
		local rpm = bit.tobit(inputs.drum - memory.encoder) / COUNTS_PER_REV / dt * 60
		if memory.measured then
			inp.drum_rpm = inp.drum_rpm + (rpm - inp.drum_rpm) * dt / (0.1 + dt)
		else -- the first measurement: the drum may be turning (a restart), start from it
			inp.drum_rpm, memory.measured = rpm, true
			drum_ramp:reset(rpm)
		end
	end
	memory.encoder, memory.time = inputs.drum, inputs.time
	return dt
end

function driver.attach(dev)
	params = dev.params
	-- What a new version continues from (its migrate gets a plain copy).
	local keep = dev.state
	keep.control = control -- the programme, the buttons and the cycle
	keep.inp = inp         -- the last inputs and the measured drum speed
	keep.memory = memory
	keep.drum_ramp, keep.drum_pid = drum_ramp, drum_pid
end

-- The first tick after recover resumed a programme: the plant must agree
-- with the checkpoint (door closed, water within RECOVER_LEVEL_L; in a fill
-- it may have risen more, as the valves stayed open until the board's
-- watchdog closed them, and in a drain or a spin fallen more), or the
-- programme is cancelled (stop, drain, unlock), saying why.
local function check_plant(dev, r)
	local why
	if not inp.door_closed then
		why = "the door is open"
	elseif type(r.level_l) ~= "number" then
		why = "the checkpoint has no water level to compare"
	elseif (inp.level_l - r.level_l > RECOVER_LEVEL_L and wash.step_name ~= "fill")
		or (r.level_l - inp.level_l > RECOVER_LEVEL_L and wash.step_name ~= "drain" and wash.step_name ~= "spin") then
		why = string.format("the water level is %.1f l, the checkpoint had %.1f l", inp.level_l, r.level_l)
	end
	control:agree(dev, why)
end

function driver.tick(dev, inputs)
	local dt = read_board(inputs)
	if recovery then
		check_plant(dev, recovery)
		recovery = nil
	end
	control:buttons(dev, inputs.start_button, inputs.cancel_button)
	wash:tick(inputs.time, inp, want)
	control:publish(dev)

	local o = dev.out
	o.hot_valve, o.cold_valve, o.drain_pump = want.hot_valve, want.cold_valve, want.drain_pump
	o.door_lock, o.motor_on = guard_lock() or want.door_lock, want.motor_on
	o.drum_drive = drive_drum(dt)

	local v = dev.vars
	v.drum_rpm, v.drum_setpoint_rpm = inp.drum_rpm, memory.setpoint_rpm
	v.level_l, v.temp_c = inp.level_l, inp.temp_c
	v.door = inputs.door_locked and "locked" or inputs.door_closed and "closed" or "open"
end

function driver.input(dev, name, value)
	return control:input(dev, name, value)
end

function driver.detach()
	all_off(want)
end

-- Recovery after a restart (docs/DRIVERS.md): after attach, before the first
-- tick, with the host's last checkpoint of dev.state. A programme that was
-- running (or paused) resumes where it was when the checkpoint is at most
-- recover_max_age_s old and the plant agrees at the first tick
-- (check_plant); older, it is cancelled at once. One that was cancelling
-- goes on cancelling. Idle or finished: nothing to resume (a finished
-- programme's status is kept). The bus clock started again: the cycle goes
-- on from os.clock(), and the encoder reading and its time are not taken
-- over (the first tick starts fresh). The door guard starts from the
-- checkpoint's, held while a programme was active, until the drum is
-- measured still and the water below the door.
function driver.recover(dev, saved)
	local old = saved.state
	if type(old) ~= "table" or type(old.control) ~= "table" or type(old.control.cycle) ~= "table" then
		return
	end
	local phase = old.control.cycle.phase
	memory.guard = phase == "running" or phase == "cancelling"
		or type(old.memory) == "table" and old.memory.guard == true
	if control:recover(dev, old.control, saved.age_s, params.recover_max_age_s) == "resume" then
		recovery = { level_l = type(old.inp) == "table" and old.inp.level_l or nil }
	end
end

-- into[name] = from[name] for each of names whose value in from (a plain
-- copy, maybe of another version's layout) has the type kind.
local function take(into, from, names, kind)
	if type(from) ~= "table" then return end
	for _, name in ipairs(names) do
		if type(from[name]) == kind then
			into[name] = from[name]
		end
	end
end

-- Any output on: the machine is doing something.
local function busy(out)
	return out.hot_valve or out.cold_valve or out.drain_pump or out.door_lock or out.motor_on
		or (out.drum_drive or 0) ~= 0
end

-- Hot reload (docs/DRIVERS.md): after attach, with the old version's
-- outputs in dev.out. The programme goes on where it was; the drum speed,
-- its loop and the door guard go on from their last values, so the first
-- tick neither brakes the drum nor lets go of the lock.
function driver.migrate(dev, old)
	if type(old.control) ~= "table" then -- 1.0.0 kept nothing in dev.state
		if busy(dev.out) then
			error("the running version keeps no state to continue from; reload when the washer is idle", 0)
		end
		return
	end
	assert(control:restore(old.control))
	if type(old.inp) == "table" then
		for name, value in pairs(old.inp) do
			local kind = type(value)
			if kind == "boolean" or kind == "number" or kind == "string" then
				inp[name] = value
			end
		end
	end
	take(memory, old.memory, { "encoder", "time", "setpoint_rpm" }, "number")
	take(memory, old.memory, { "guard", "measured" }, "boolean")
	memory.measured = memory.measured or memory.time ~= nil -- 1.1.0 measured from its first tick on
	take(drum_ramp, old.drum_ramp, { "value", "rate", "target" }, "number")
	take(drum_pid, old.drum_pid, { "i_term", "p_term", "d_term", "output" }, "number")
end

return driver
