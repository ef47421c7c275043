-- Tests of the worked example in docs/STDLIB.md: the washer driver, loaded
-- from the document as it stands, in a driver sandbox, against the washer
-- plant (tests/lua/washer_plant.lua) in virtual time at 33 Hz.

local T = require "testing"
local washer_plant = require "washer_plant"
local test = T.test

local PERIOD_S = 0.03

-- A fresh driver, plant and bus. The driver is the lua block after the
-- example marker of docs/STDLIB.md, as tests/lua/run.c reads it, run in
-- this case's own driver state (every case gets a fresh one, as each
-- machine has its own), so a case makes one washer at most.
local made = false
local function new_washer(plant_spec)
	assert(not made, "new_washer: one washer per test case (the example's state is the module's)")
	made = true
	local driver = require "washer_example"
	local plant = washer_plant.new(plant_spec)
	local bus = washer_plant.bus(driver, plant, PERIOD_S)
	return driver, plant, bus
end

-- Run until stop(t, status) is true or max_s passes; returns the status.
local function run_until(driver, bus, max_s, stop)
	local status
	local reached = bus.run(max_s, function(t)
		status = driver.status()
		return stop(t, status)
	end)
	T.check(reached, "condition not reached within %g s (state %s, step %s, error %s)", max_s,
		tostring(status and status.state), tostring(status and status.step), tostring(status and status.error))
	return status
end

local function outputs_off(bus)
	local out = bus.pending
	for i = 1, 7 do
		if out.digital[i] then return false end
	end
	return out.pwm == 0
end

test("the whole wash: fill, 45 RPM wash, drain, rinse, 400 RPM spin, unlocked and empty", function()
	local driver, plant, bus = new_washer()
	bus.run(1)
	T.equal(driver.start(true), true, "start()")
	local seen, step_started, last_rpm, fastest = {}, nil, 0, 0
	local step, fills = nil, {}
	local status = run_until(driver, bus, 1500, function(t, s)
		if s.step ~= step then
			if step == "fill" or step == "rinse fill" then fills[#fills + 1] = plant.water_l end
			step, step_started = s.step, t
			seen[#seen + 1] = s.step
		end
		local in_step = t - step_started
		if step == "wash" and in_step > 10 and in_step < 480 then
			T.near(plant.rpm, 45, 1, "drum speed %.0f s into the wash (t=%.2f s)", in_step, t)
		elseif step == "spin" and in_step > 15 and in_step < 300 then
			T.near(plant.rpm, 400, 4, "drum speed %.0f s into the spin (t=%.2f s)", in_step, t)
		end
		local accel = math.abs(plant.rpm - last_rpm) / PERIOD_S
		if accel > fastest then fastest = accel end
		last_rpm = plant.rpm
		if math.abs(plant.rpm) > 5 or plant.water_l > 1 then
			T.check(plant.door_locked, "door unlocked with the drum at %.1f RPM and %.1f l in (t=%.2f s, %s)",
				plant.rpm, plant.water_l, t, step)
		end
		return s.state ~= "running"
	end)
	T.equal(status.state, "done", "state at the end")
	T.equal(status.error, nil, "error at the end")
	T.equal(table.concat(seen, ","), "lock,fill,wash,drain,rinse fill,rinse,drain,spin,unlock", "steps run")
	T.equal(#fills, 2, "fills")
	T.near(fills[1], 12, 0.2, "litres after the hot fill")
	T.near(fills[2], 12, 0.2, "litres after the rinse fill")
	T.at_most(fastest, 55, "fastest change of drum speed (RPM/s; the ramp allows 50)")
	T.near(plant.t, 1124, 30, "bus time at the end")
	bus.run(0.1)
	T.equal(plant.door_locked, false, "door locked at the end")
	T.at_most(plant.water_l, 0.5, "litres left at the end")
	T.check(outputs_off(bus), "outputs all off at the end")
end)

test("pause, open the door, resume, close it: the wash goes on with the time it had left", function()
	local driver, plant, bus = new_washer()
	bus.run(0.3)
	driver.start(false)
	run_until(driver, bus, 200, function(_, s) return s.step == "wash" and s.left_s and s.left_s < 400 end)
	local left_before = driver.status().left_s
	T.equal(driver.pause(), true, "pause()")
	-- The door stays locked while the drum turns; try to open it every tick.
	local opened_at
	run_until(driver, bus, 120, function(t)
		if plant.set_door(false) then
			opened_at = t
			return true
		end
		T.check(plant.door_locked, "door neither locked nor openable at t=%.2f s", t)
	end)
	T.at_most(math.abs(plant.rpm), 5, "drum speed (RPM) when the door could be opened")
	bus.run(0.1)
	local s = driver.status()
	T.equal(s.state, "paused", "state with the door open")
	T.equal(s.door, "tripped", "door interlock with the door open")
	T.equal(driver.resume(), true, "resume() by the user")
	bus.run(30, function(t)
		T.check(outputs_off(bus), "outputs with the door open at t=%.2f s", t)
		T.equal(driver.status().state, "paused", "state with the door open at t=%.2f s", t)
	end)
	T.equal(driver.status().paused_by, "door open", "pause reason after the user's resume")
	plant.set_door(true)
	local closed_at = plant.t
	local resumed = run_until(driver, bus, 5, function(_, st) return st.state == "running" end)
	T.at_most(plant.t - closed_at, 0.3, "seconds from door closed to running again")
	T.equal(plant.door_locked, true, "door locked when the wash resumed")
	T.equal(resumed.step, "wash", "step after resuming")
	T.near(resumed.left_s, left_before, 2 * PERIOD_S, "seconds of washing left, before the pause and after")
	T.check(opened_at ~= nil, "the door was opened")
	bus.run(20)
	T.near(plant.rpm, 45, 1, "drum speed 20 s after resuming")
end)

test("cancel during the wash: the drum stops, the tub drains, the door unlocks", function()
	local driver, plant, bus = new_washer()
	bus.run(0.3)
	driver.start(true)
	run_until(driver, bus, 200, function(_, s) return s.step == "wash" and s.left_s and s.left_s < 420 end)
	T.near(plant.water_l, 12, 0.2, "litres in the tub at the cancel")
	T.equal(driver.cancel(), true, "cancel()")
	local status = run_until(driver, bus, 120, function(t, s)
		if math.abs(plant.rpm) > 5 or plant.water_l > 1 then
			T.check(plant.door_locked, "door unlocked while cancelling (%.1f RPM, %.1f l, t=%.2f s)",
				plant.rpm, plant.water_l, t)
		end
		return s.state ~= "cancelling" and s.state ~= "paused"
	end)
	T.equal(status.state, "cancelled", "state after the cleanup")
	bus.run(0.1)
	T.at_most(plant.water_l, 0.5, "litres left")
	T.at_most(math.abs(plant.rpm), 5, "drum speed (RPM)")
	T.equal(plant.door_locked, false, "door locked after the cancel")
	T.check(outputs_off(bus), "outputs all off after the cancel")
	local ok, message = driver.cancel()
	T.equal(ok, nil, "cancel() again")
	T.equal(message, "cycle is not running", "cancel() again: message")
end)

test("a fill that never completes fails in 'fill' after 120 s and drains", function()
	local driver, plant, bus = new_washer({ fill_rate_lps = 0.05 })
	bus.run(0.3)
	driver.start(true)
	local status = run_until(driver, bus, 400, function(_, s) return s.state == "failed" end)
	T.equal(status.error, "fill: timed out after 120 s waiting for 12 l of water", "error")
	T.near(plant.t, 0.3 + 120 + 6 + 5, 3, "bus time of the failure (120 s fill, drain, 5 s more)")
	bus.run(0.1)
	T.at_most(plant.water_l, 0.5, "litres left")
	T.equal(plant.door_locked, false, "door locked after the failure")
	T.check(outputs_off(bus), "outputs all off after the failure")
end)

test("started with the door open, the washer waits, then locks and fills", function()
	local driver, plant, bus = new_washer()
	plant.set_door(false)
	bus.run(0.3)
	driver.start(true)
	bus.run(10, function(t)
		T.check(outputs_off(bus), "outputs with the door open at t=%.2f s", t)
	end)
	T.equal(driver.status().paused_by, "door open", "pause reason")
	plant.set_door(true)
	local status = run_until(driver, bus, 5, function(_, s) return s.step == "fill" end)
	T.equal(status.state, "running", "state once the door closed")
	bus.run(1)
	T.equal(plant.door_locked, true, "door locked while filling")
	T.check(bus.pending.digital[1], "hot valve open while filling")
end)
