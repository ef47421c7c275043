-- The washer driver (scripts/drivers/washer.lua) and its programmes
-- (scripts/cycles/washer/), against the washer plant in virtual time.
-- Run: build/bin/vmac test tests/drivers/washer_test.lua (docs/TESTING.md)

local STILL_RPM, DOOR_LEVEL_L = 2, 5

-- A washer board, attached and idle. time_scale shortens the timed steps
-- (washing, spinning); fills and drains keep their real length.
local function washer(time_scale)
	local w = board { name = "washer-1", plant = "washer", params = { time_scale = time_scale or 0.05 } }
	run_until(function() return w.var.state == "idle" end, 5, "the washer attached and idle")
	return w
end

-- The rules no programme may break, checked at every tick.
local function door_rules(w)
	always("the drum turns only behind a locked door", function()
		return math.abs(w.plant.drum_rpm) < STILL_RPM + 1 or w.plant.door_locked
	end)
	always("the door lock is held while the drum turns or water is above the door", function()
		return w.out.door_lock or (math.abs(w.plant.drum_rpm) < STILL_RPM + 1 and w.plant.water_l <= DOOR_LEVEL_L + 0.5)
	end)
end

-- Record the steps the washer publishes, in order, without repeats.
local function step_log(w)
	local steps = {}
	always("(recording steps)", function()
		local s = w.var.step
		if s and s ~= "-" and steps[#steps] ~= s then steps[#steps + 1] = s end
		return true
	end)
	return steps
end

-- Run the cycle to its end; it must end "done".
local function finish(w, what)
	run_until(function()
		local s = w.var.state
		return s == "done" or s == "failed" or s == "cancelled"
	end, 3600, what or "the end of the programme")
	expect_eq(w.var.state, "done", "end state (error: " .. tostring(w.var.error) .. ")")
end

local function all_off(w)
	return not (w.out.hot_valve or w.out.cold_valve or w.out.motor_on or w.out.drain_pump) and w.out.drum_drive == 0
end

local PROGRAMMES = {
	{ "quick", litres = 8, steps = "lock fill wash drain fill rinse drain spin unlock" },
	{ "normal", litres = 12, steps = "lock fill wash drain fill rinse drain spin unlock" },
	{ "delicate", litres = 15, steps = "lock fill wash drain fill rinse drain fill rinse drain spin unlock" },
}

for _, p in ipairs(PROGRAMMES) do
	local name = p[1]
	test(name .. " programme: fills before it agitates, never spins unlocked, ends unlocked and off", function()
		local w = washer(0.05)
		door_rules(w)
		local steps = step_log(w)
		local agitated = false
		always("the drum first turns with the tub filled", function()
			if w.out.motor_on and not agitated then
				agitated = true
				return w.plant.water_l >= p.litres - 0.1
			end
			return true
		end)
		w:input("start", name)
		run_until(function() return w.var.state == "running" end, 1, "the cycle to start")
		expect_eq(w.var.cycle, name, "programme running")
		finish(w, "the end of the " .. name .. " programme")
		expect(agitated, "the drum to have turned")
		if p.steps then expect_eq(table.concat(steps, " "), p.steps, "steps") end
		expect_eq(w.var.error, "", "error")
		-- Outputs reach the board with its next service.
		eventually(function() return all_off(w) end, 0.1, "every output off after the cycle")
		-- The lock is held until the coasting drum has clearly stopped.
		eventually(function() return not w.out.door_lock end, 10, "the door unlocked after the cycle")
		expect(w.plant.water_l < 0.5, "an empty tub after the cycle")
		expect_eq(w.state, "running", "the host's view of the washer")
	end)
end

test("the drum reaches the spin speed and the wash speed on its loop", function()
	local w = washer(0.2)
	w:input("start", "quick")
	run_until(function() return w.var.step == "wash" end, 120, "the wash step")
	run_for(20)
	expect_near(w.plant.drum_rpm, 45, 5, "drum speed while washing (rpm)")
	run_until(function() return w.var.step == "spin" end, 600, "the spin step")
	run_for(20)
	expect_near(w.plant.drum_rpm, 400, 20, "drum speed while spinning (rpm)")
end)

test("start is refused while the door is open", function()
	local w = washer()
	w:open_door()
	run_until(function() return w.var.door == "open" end, 1, "the driver seeing the open door")
	local ok, why = w:try_input("start", "quick")
	expect(not ok, "start to be refused")
	expect(why:find("close the door", 1, true), "a reason naming the door, got: " .. tostring(why))
	w:close_door()
	run_until(function() return w.var.door == "closed" end, 1, "the driver seeing the closed door")
	w:input("start", "quick")
	run_until(function() return w.var.state == "running" end, 1, "the cycle to start")
end)

test("the door cannot be opened while the washer fills", function()
	local w = washer()
	w:input("start", "quick")
	run_until(function() return w.var.step == "fill" and w.plant.water_l > 2 end, 60, "the tub filling")
	expect(not w:try_set("door", 0), "the locked door to refuse opening")
	expect(w.plant.door_closed, "the door still closed")
end)

-- The emergency release opens a locked door at any point: everything goes
-- off within a service, the cycle pauses, and resumes once the door is
-- closed again, to finish normally.
for _, at in ipairs { "fill", "wash", "rinse", "spin" } do
	test("door opened by the emergency release during " .. at .. ": all off, pause, resume, finish", function()
		local w = washer(0.05)
		w:input("start", "quick")
		run_until(function() return w.var.step == at end, 600, "the " .. at .. " step")
		run_for(2)
		w:set("door_release")
		eventually(function() return all_off(w) and not w.out.door_lock end, 0.05,
			"every valve, pump, the motor and the lock solenoid off")
		run_until(function() return w.var.state == "paused" end, 1, "the cycle paused")
		expect_eq(w.var.paused_by, "door open", "paused by")
		always("nothing runs while the door is open", function()
			return w.plant.door_closed or all_off(w) and not w.out.door_lock
		end)
		run_for(10)
		expect_eq(w.var.step, at, "the step while paused")
		w:close_door()
		run_until(function() return w.var.state == "running" end, 10, "the cycle resumed")
		expect(w.plant.door_locked, "the door locked again before resuming")
		finish(w)
		expect_eq(w.var.error, "", "error")
	end)
end

test("cancel during the wash: the drum stops, the tub drains, the door unlocks", function()
	local w = washer(0.05)
	door_rules(w)
	w:input("start", "quick")
	run_until(function() return w.var.step == "wash" end, 120, "the wash step")
	run_for(3)
	w:input("cancel")
	run_until(function() return w.var.state == "cancelled" end, 600, "the cancel to complete")
	expect(w.plant.water_l < 0.5, "the tub drained")
	expect(math.abs(w.plant.drum_rpm) < STILL_RPM, "the drum still")
	eventually(function() return all_off(w) end, 0.1, "every output off")
	eventually(function() return not w.out.door_lock end, 10, "the door unlocked")
end)

test("the cancel button on the machine does what the cancel command does", function()
	local w = washer(0.05)
	w:input("start", "quick")
	run_until(function() return w.var.step == "fill" end, 10, "the fill step")
	w:press("cancel")
	run_until(function() return w.var.state == "cancelled" end, 600, "the cancel to complete")
end)

test("the start button on the machine starts the chosen programme", function()
	local w = board { name = "washer-1", plant = "washer", params = { time_scale = 0.05, program = "delicate" } }
	run_until(function() return w.var.state == "idle" end, 5, "the washer attached and idle")
	w:press("start")
	run_until(function() return w.var.state == "running" end, 1, "the programme running")
	expect_eq(w.var.cycle, "delicate", "the programme the button started")
end)

test("a slow fill that times out fails the cycle safely", function()
	local w = board { name = "washer-1", plant = "washer", params = { time_scale = 0.05, fill_timeout_s = 30 } }
	run_until(function() return w.var.state == "idle" end, 5, "the washer attached")
	w:set("fill_rate_lps", 0.05)
	w:input("start", "quick")
	run_until(function() return w.var.state == "failed" end, 600, "the cycle to fail")
	expect(w.var.error:find("fill", 1, true), "the error to name the fill step, got: " .. w.var.error)
	run_until(function() return all_off(w) and not w.out.door_lock end, 300, "every output off, door unlocked")
end)

test("the washer board dropping out mid-cycle: driver unloaded, board safe, the kitchen goes on", function()
	local k = kitchen { params = { washer = { time_scale = 0.05 } } }
	local w, l = k.washer, k.lights
	run_until(function() return w.var.state == "idle" and l.state == "running" end, 5, "the kitchen attached")
	w:input("start", "quick")
	run_until(function() return w.var.step == "wash" end, 120, "the wash step")
	run_for(2)
	expect(w.out.motor_on, "the motor running before the drop")
	w:unplug()
	local dropped_at = now()
	run_until(function() return w.state == "errant" end, 1, "the host to drop the washer")
	expect_event({ kind = "dropped", device = "washer-1" }, "a drop event")
	expect_eq(w.var.state, nil, "published variables after the driver is unloaded")
	-- The board's own watchdog turns everything off.
	run_until(function() return all_off(w) end, 1, "the board's outputs off")
	expect(now() - dropped_at < 1, "the outputs off within the watchdog period")
	-- The rest of the kitchen did not notice.
	expect_eq(l.device.misses, 0, "misses of the lights board")
	l:set("toggle1")
	run_until(function() return l.out.kitchen end, 0.5, "the kitchen light on from its wall switch")
	-- Plugged in again, the washer announces itself, attaches afresh and
	-- resumes the wash from its last checkpoint (docs/DRIVERS.md "Recovery").
	w:replug()
	run_until(function() return w.var.state == "running" end, 5, "the washer attached again, running")
	expect_eq(w.var.step, "wash", "the step it resumed at")
	expect_event({ kind = "driver", device = "washer-1", text = "recovered: resuming quick at step wash" },
		"an event saying the programme resumed")
end)

test("a board that answers later than the deadline is dropped", function()
	local w = washer()
	w:faults { late = 0.006 } -- the reply deadline is 4 ms
	run_until(function() return w.state == "errant" end, 1, "the host to drop the washer")
	local e = expect_event({ kind = "dropped", device = "washer-1" }, "a drop event")
	expect(e.text:find("after the request", 1, true) or e.text:find("no reply", 1, true),
		"the drop to say why, got: " .. e.text)
end)

test("a board powered off mid-cycle is dropped and its outputs are off", function()
	local w = washer(0.05)
	w:input("start", "quick")
	run_until(function() return w.var.step == "fill" end, 10, "the fill step")
	w:power_off()
	run_until(function() return w.state == "errant" end, 1, "the host to drop the washer")
	expect(all_off(w), "every output off")
	w:power_on()
	-- The tub kept its water: the washer resumes the fill where it was.
	run_until(function() return w.var.state == "running" end, 5, "the washer attached again, running")
	expect_eq(w.var.step, "fill", "the step it resumed at")
	run_until(function() return w.var.step == "wash" end, 60, "the fill to finish and the wash to begin")
end)

test("corrupted frames are refused, and a board whose every frame is corrupted is dropped", function()
	local w = washer()
	w:faults { corrupt = 1 }
	run_until(function() return w.state == "errant" end, 1, "the host to drop the washer")
	w:faults {}
	run_until(function() return w.var.state == "idle" end, 5, "the washer attached again")
end)

test("with a miss limit of 3, a lossy link (1% of frames lost) does not stop the cycle", function()
	config { miss_limit = 3 }
	local w = washer(0.05)
	w:faults { drop = 0.01 }
	w:input("start", "quick")
	finish(w)
	expect(w.device.misses > 0, "some misses counted")
end)

-- ---- recovery after a host crash (docs/DRIVERS.md "Recovery after a restart") ----

local function unsafe_door(w)
	local p = w.plant
	return p.door_closed and not p.door_locked and (math.abs(p.drum_rpm) > 2 or p.water_l > 5)
end

test("a host crash mid-wash: the boards go safe, and the new host resumes the wash where it was", function()
	local w = washer(0.05)
	always("the door locked while the drum turns or water is above the door", function() return not unsafe_door(w) end)
	w:input("start", "quick")
	run_until(function() return w.var.step == "wash" end, 120, "the wash step")
	run_for(1)
	local left = w.var.time_left_s
	crash_host()
	run_until(function() return all_off(w) end, 1, "the board's watchdog to turn every output off")
	expect_eq(w.state, "absent", "the host's view of the washer while there is no host")
	run_for(1) -- the PTC lock holds the door meanwhile (docs/BOARD.md)
	start_host()
	run_until(function() return w.var.state == "running" end, 5, "the washer running again")
	expect_eq(w.var.step, "wash", "the step it resumed at")
	expect(w.var.time_left_s <= left + 1, "the wash goes on with the time it had left (" .. tostring(w.var.time_left_s)
		.. " s, " .. tostring(left) .. " s before the crash)")
	expect_event({ kind = "recovered", device = "washer-1" }, "the host's recovered event")
	run_until(function() return w.var.state == "done" end, 600, "the programme to finish")
	run_until(function() return not w.out.door_lock end, 30, "the door unlocked once the drum is still")
end)

test("a host down for longer than recover_max_age_s: the washer drains and unlocks, saying why", function()
	local w = board { name = "washer-1", plant = "washer", params = { time_scale = 0.05, recover_max_age_s = 30 } }
	run_until(function() return w.var.state == "idle" end, 5, "the washer attached and idle")
	always("the door locked while the drum turns or water is above the door", function() return not unsafe_door(w) end)
	w:set("lock_release_s", 120) -- a real PTC lock: it stays locked through this outage
	w:input("start", "quick")
	run_until(function() return w.var.step == "wash" end, 120, "the wash step")
	crash_host()
	run_for(60)
	start_host()
	run_until(function() return w.var.state == "cancelling" or w.var.state == "cancelled" end, 5,
		"the programme cancelled")
	expect_event({ kind = "driver", device = "washer-1", text = "more than 30 s" }, "an event saying why")
	run_until(function() return w.plant.water_l < 0.5 and not w.out.door_lock end, 600, "drained and unlocked")
end)
