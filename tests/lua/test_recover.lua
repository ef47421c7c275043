-- Tests of recovery after a restart (docs/DRIVERS.md "Recovery after a
-- restart") in the shipped drivers: an instance runs on a simulated plant
-- while a fake host checkpoints its dev.state (tests/lua/fake_host.lua), the
-- host "restarts" (the boards go safe, the bus clock starts again at 0), and
-- a new instance of the driver gets recover(dev, saved) with the last
-- checkpoint, then ticks on the same plant.

local T = require "testing"
local fake_host = require "fake_host"
local washer_plant = require "washer_plant"
local dishwasher_plant = require "dishwasher_plant"
local host_copy = require "host_copy"
local test = T.test

-- Timed steps at 1/20 of their length: the normal wash's 8 minutes take 24 s.
local PARAMS = { time_scale = 0.05 }
local WASH_S = 8 * 60 * 0.05
local DOOR_LEVEL_L, STILL_RPM = 5, 2
local PERIOD_S = 0.03

-- A washer running the normal programme, stopped once the wash has run for
-- washed_s and a checkpoint (every 5 s) was taken inside the wash.
local function washer_washing(washed_s)
	local driver = require "driver_washer"
	local host = fake_host.new(driver, washer_plant.new(), { params = PARAMS })
	host.run(0.3)
	T.equal(driver.input(host.dev, "start", "normal"), true, "start the normal programme")
	local v = host.dev.vars
	T.check(host.run(300, function()
		return v.step == "wash" and v.time_left_s <= WASH_S - washed_s
			and host.saved_vars.step == "wash" and host.saved_vars.time_left_s < WASH_S - 1
	end), "the washer never got %g s into its wash with a checkpoint there (step %s)", washed_s, tostring(v.step))
	return host
end

-- Every tick of the recovered washer: the driver asks for the door lock
-- while the drum turns or the water is above the door (from the first tick),
-- and from the second tick on the board has it locked.
local function door_rules(host)
	local plant, ticks = host.plant, 0
	return function(t)
		ticks = ticks + 1
		if math.abs(plant.rpm) >= STILL_RPM or plant.water_l > DOOR_LEVEL_L then
			T.check(host.dev.out.door_lock, "door lock output off with the drum at %.1f RPM and %.1f l in (t=%.2f s)",
				plant.rpm, plant.water_l, t)
			if ticks > 1 then
				T.check(plant.door_locked, "door unlocked with the drum at %.1f RPM and %.1f l in (t=%.2f s)",
					plant.rpm, plant.water_l, t)
			end
		end
	end
end

-- Run until the programme has ended (done, cancelled, failed); returns the
-- steps seen, in order.
local function run_to_end(host, max_s, rules)
	local v, steps = host.dev.vars, {}
	local ended = host.run(max_s, function(t)
		if rules then rules(t) end
		if v.step ~= steps[#steps] then steps[#steps + 1] = v.step end
		return v.state == "done" or v.state == "cancelled" or v.state == "failed"
	end)
	T.check(ended, "the programme did not end within %g s (state %s, step %s, events: %s)", max_s,
		tostring(v.state), tostring(v.step), host.event_text())
	return steps
end

-- After the end: the door unlocks once the coasting drum has clearly
-- stopped, the tub is empty and every output off.
local function washer_safe_at_end(host)
	local plant, out = host.plant, host.dev.out
	T.check(host.run(30, function() return not plant.door_locked end),
		"the door still locked 30 s after the end (drum %.1f RPM, %.1f l)", plant.rpm, plant.water_l)
	T.at_most(plant.water_l, 0.5, "litres left in the tub")
	T.at_most(math.abs(plant.rpm), STILL_RPM, "drum speed (RPM) when the door unlocked")
	T.check(not (out.hot_valve or out.cold_valve or out.drain_pump or out.motor_on) and out.drum_drive == 0,
		"outputs all off at the end")
end

test("washer: a fresh checkpoint mid-wash resumes the wash with the time it had left, then finishes", function()
	local old = washer_washing(10)
	local left = old.saved_vars.time_left_s
	fake_host.outage(old.plant, 1)
	local water = old.plant.water_l
	local host = fake_host.recover(old, require "driver_washer", 30, { params = PARAMS })
	T.equal(host.dev.out.door_lock, nil, "outputs before the first tick (they start off)")

	host.tick()
	local v = host.dev.vars
	T.equal(host.events[1], "recovered: resuming normal at step wash (checkpoint 30 s old)", "the recovery event")
	T.equal(v.state, "running", "state after the first tick")
	T.equal(v.step, "wash", "step after the first tick")
	T.near(v.time_left_s, left, 2 * PERIOD_S, "seconds of washing left: at the checkpoint, and after the restart")
	T.equal(host.dev.out.door_lock, true, "door lock output at the first tick (%.1f l in)", water)
	T.equal(host.dev.out.motor_on, true, "motor output at the first tick")
	T.equal(host.levels[1], 4, "service level asked for (running)")
	T.check(host.asked >= 1, "the first publish asks for a checkpoint")

	local rules = door_rules(host)
	host.run(8, rules)
	T.near(host.plant.rpm, 45, 3, "drum speed 8 s after the restart (from the coasting speed, a fresh loop)")
	T.near(host.plant.water_l, water, 0.1, "litres in the tub: no new fill")
	local steps = run_to_end(host, 400, rules)
	T.equal(v.state, "done", "end state (error: %s)", tostring(v.error))
	T.equal(table.concat(steps, ","), "wash,drain,fill,rinse,drain,spin,unlock", "steps after the restart")
	washer_safe_at_end(host)
end)

test("washer: a checkpoint older than recover_max_age_s cancels: the drum stops, the tub drains, the door unlocks",
	function()
		local old = washer_washing(10)
		fake_host.outage(old.plant, 1)
		local host = fake_host.recover(old, require "driver_washer", 700, { params = PARAMS })
		T.equal(host.events[1], "recovery: checkpoint 700 s old, more than 600 s: cancelling normal at step wash",
			"the event, before the first tick")
		local rules = door_rules(host)
		host.tick()
		rules(host.plant.t)
		T.equal(host.dev.vars.state, "cancelling", "state after the first tick")
		T.equal(host.dev.out.door_lock, true, "door lock output at the first tick (%.1f l in)", host.plant.water_l)
		T.equal(host.dev.out.motor_on and host.dev.out.drum_drive ~= 0, false, "the drum driven while cancelling")
		run_to_end(host, 200, rules)
		T.equal(host.dev.vars.state, "cancelled", "end state (error: %s)", tostring(host.dev.vars.error))
		washer_safe_at_end(host)
	end)

test("washer: a water level that disagrees with the checkpoint cancels at the first tick, saying so", function()
	local old = washer_washing(10)
	fake_host.outage(old.plant, 1)
	old.plant.water_l = 4 -- drained (or leaked) while the host was away
	local host = fake_host.recover(old, require "driver_washer", 30, { params = PARAMS })
	T.equal(#host.events, 0, "events before the first tick")
	host.tick()
	local saved_level = old.saved.inp.level_l
	T.equal(host.events[1], string.format("recovery: the water level is 4.0 l, the checkpoint had %.1f l: "
		.. "cancelling normal at step wash (checkpoint 30 s old)", saved_level), "the event at the first tick")
	T.equal(host.dev.vars.state, "cancelling", "state after the first tick")
	run_to_end(host, 200, door_rules(host))
	T.equal(host.dev.vars.state, "cancelled", "end state")
	washer_safe_at_end(host)
end)

test("washer: a door found open at the first tick cancels, and the drain waits for the door", function()
	local old = washer_washing(10)
	fake_host.outage(old.plant, 1)
	T.equal(old.plant.set_door(false), true, "opening the door while the host is away (its lock off)")
	local host = fake_host.recover(old, require "driver_washer", 30, { params = PARAMS })
	host.tick()
	T.check(host.events[1] and host.events[1]:find("recovery: the door is open: cancelling normal at step wash", 1, true),
		"the event at the first tick, got %q", host.event_text())
	host.run(5)
	T.equal(host.dev.vars.paused_by, "door open", "the cleanup held by the open door")
	T.check(not host.dev.out.drain_pump and not host.dev.out.motor_on, "pump or motor on with the door open")
	host.plant.set_door(true)
	run_to_end(host, 200, door_rules(host))
	T.equal(host.dev.vars.state, "cancelled", "end state")
	washer_safe_at_end(host)
end)

test("washer: with no programme to resume, the guard locks the door from the first tick while water is above it",
	function()
		local old = washer_washing(10)
		fake_host.outage(old.plant, 1)
		-- As if the programme had failed with the water in (its drain timed out).
		local cycle = old.saved.control.cycle
		cycle.phase, cycle.state, cycle.error = "failed", "failed", "drain: timed out after 180 s waiting for an empty tub"
		local host = fake_host.recover(old, require "driver_washer", 30, { params = PARAMS })
		host.tick()
		T.equal(#host.events, 0, "events (nothing resumed or cancelled), got: %s", host.event_text())
		T.equal(host.dev.vars.state, "failed", "state kept from the checkpoint")
		T.equal(host.dev.vars.error, cycle.error, "error kept from the checkpoint")
		T.equal(host.dev.out.door_lock, true, "door lock output at the first tick with %.1f l in", host.plant.water_l)
		host.run(5, door_rules(host))
		T.equal(host.plant.set_door(false), false, "opening the door with the water above it")
		host.plant.water_l = 1 -- drained by hand; the drum still coasts from the wash
		T.check(host.run(60, function() return not host.dev.out.door_lock end), "the door lock was never let go")
		T.at_most(math.abs(host.plant.rpm), STILL_RPM, "drum speed (RPM) when the lock was let go")
	end)

test("washer: recovered while the drum still coasts from the spin, the guard holds the lock until it is still",
	function()
		local driver = require "driver_washer"
		local old = fake_host.new(driver, washer_plant.new(), { params = PARAMS })
		old.run(0.3)
		driver.input(old.dev, "start", "normal")
		T.check(old.run(400, function() return old.dev.vars.step == "spin" and old.plant.rpm > 350 end),
			"the washer never reached the spin")
		local before = old.saved_time
		T.check(old.run(6, function() return old.saved_time ~= before end), "no checkpoint at full speed")
		T.equal(old.saved.memory.guard, true, "the guard at the checkpoint")
		fake_host.outage(old.plant, 0.5)
		T.at_least(old.plant.rpm, 100, "drum speed (RPM) after the outage")
		local cycle = old.saved.control.cycle -- as if the spin had failed just then: nothing to resume
		cycle.phase, cycle.state, cycle.error = "failed", "failed", "spin: motor fault"
		local host = fake_host.recover(old, require "driver_washer", 5, { params = PARAMS })
		local rules = door_rules(host)
		T.check(host.run(120, function(t)
			rules(t)
			return not host.dev.out.door_lock
		end), "the door lock was never let go")
		T.at_most(math.abs(host.plant.rpm), STILL_RPM, "drum speed (RPM) when the lock was let go")
	end)

test("washer: a hot reload (migrate) still continues the wash on the same clock without braking the drum", function()
	local old = washer_washing(10)
	local left, drive = old.dev.vars.time_left_s, old.dev.out.drum_drive
	local host = fake_host.new(require "driver_washer", old.plant, { params = PARAMS })
	for name, value in pairs(old.dev.out) do host.dev.out[name] = value end
	host.pending = old.pending
	host.driver.migrate(host.dev, host_copy.state(old.dev.state))
	host.tick()
	T.equal(host.dev.vars.step, "wash", "step after the reload")
	T.near(host.dev.vars.time_left_s, left - PERIOD_S, 1e-6, "seconds of washing left")
	T.near(host.dev.out.drum_drive, drive, 30, "drum drive at the first tick of the new version")
	T.equal(#host.events, 0, "events (a reload is no recovery)")
	host.run(5)
	T.near(host.plant.rpm, 45, 1, "drum speed 5 s after the reload")
end)

-- The dishwasher in the middle of its main wash.
local function dishwasher_washing()
	local driver = require "driver_dishwasher"
	local host = fake_host.new(driver, dishwasher_plant.new(), { params = PARAMS })
	host.run(0.3)
	T.equal(driver.input(host.dev, "start", "normal"), true, "start the normal programme")
	local v = host.dev.vars
	T.check(host.run(300, function()
		return v.step == "wash" and host.saved_vars.step == "wash" and host.saved_vars.time_left_s < 50
	end), "the dishwasher never got into its wash with a checkpoint there (step %s)", tostring(v.step))
	return host
end

test("dishwasher: a fresh checkpoint resumes the wash with the time it had left", function()
	local old = dishwasher_washing()
	local left = old.saved_vars.time_left_s
	fake_host.outage(old.plant, 1)
	local host = fake_host.recover(old, require "driver_dishwasher", 30, { params = PARAMS })
	host.tick()
	T.equal(host.events[1], "recovered: resuming normal at step wash (checkpoint 30 s old)", "the recovery event")
	T.equal(host.dev.vars.step, "wash", "step after the first tick")
	T.near(host.dev.vars.time_left_s, left, 2 * PERIOD_S, "seconds of washing left")
	T.equal(host.dev.out.wash_motor, true, "wash motor at the first tick")
	T.equal(host.levels[1], 5, "service level asked for (running)")
	local steps = run_to_end(host, 400)
	T.equal(host.dev.vars.state, "done", "end state (error: %s)", tostring(host.dev.vars.error))
	T.equal(steps[1] .. "," .. steps[2], "wash,drain", "steps after the restart")
end)

test("dishwasher: too old, or the water gone, cancels and drains, saying why", function()
	local old = dishwasher_washing()
	fake_host.outage(old.plant, 1)
	local host = fake_host.recover(old, require "driver_dishwasher", 3600, { params = PARAMS })
	T.equal(host.events[1], "recovery: checkpoint 3600 s old, more than 600 s: cancelling normal at step wash",
		"the event for an old checkpoint")
	run_to_end(host, 100)
	T.equal(host.dev.vars.state, "cancelled", "end state after an old checkpoint")
	T.at_most(host.plant.water_l, 0.05, "litres left after the cancel")

	local again = dishwasher_washing()
	fake_host.outage(again.plant, 1)
	again.plant.water_l = 0.5
	host = fake_host.recover(again, require "driver_dishwasher", 30, { params = PARAMS })
	host.tick()
	T.check(host.events[1] and host.events[1]:find("recovery: the water level is 0.5 l, the checkpoint had ", 1, true),
		"the event for a level that disagrees, got %q", host.event_text())
	T.equal(host.dev.vars.state, "cancelling", "state after the first tick")
end)

-- The lights' board: two wall switches in, four relays out.
local function lights_board()
	local b = { switches = { false, false }, applied = {}, t = 0 }
	function b.actuate(outputs) b.applied = outputs and outputs.digital or {} end
	function b.step(dt) b.t = b.t + dt end
	function b.sense()
		return { digital = { b.switches[1], b.switches[2] }, analog = { 0, 0 }, encoder = 0, time = b.t }
	end
	return b
end

test("lights: recover switches back on the lights that were on, not the garbage disposal", function()
	local driver = require "driver_lights"
	local old = fake_host.new(driver, lights_board())
	old.run(0.1)
	driver.input(old.dev, "kitchen", true)
	driver.input(old.dev, "tv", true)
	driver.input(old.dev, "disposal", true)
	old.run(6) -- a checkpoint (every 5 s)
	fake_host.outage(old.plant, 10)
	old.plant.switches[1] = true -- the kitchen switch flipped while the host was away

	local host = fake_host.recover(old, require "driver_lights", 60)
	T.equal(host.events[1], "recovery: the garbage disposal was on; left off", "the event")
	host.run(0.1)
	local out = host.dev.out
	T.equal(out.kitchen, true, "kitchen light after the restart")
	T.equal(out.tv, true, "TV after the restart")
	T.equal(out.dining, false, "dining light after the restart (was off)")
	T.equal(out.disposal, false, "garbage disposal after the restart")
	T.equal(host.dev.vars.kitchen, true, "kitchen light published")
	T.equal(host.plant.applied[1], true, "kitchen relay on the board")
	host.plant.switches[1] = false
	host.run(0.1)
	T.equal(out.kitchen, false, "kitchen light after flipping its switch")
end)
