-- tests/dryer_test.lua: the dryer driver (dryer.lua), its programmes
-- (cycles/dryer/) and its plant (plants/dryer.lua), in virtual time.
-- Run: vmac test --drivers . tests/   (docs/TESTING.md)

local function dryer(params)
	local d = board { name = "dryer-1", plant = "dryer", params = params or { time_scale = 0.05 } }
	run_until(function() return d.var.state == "idle" end, 5, "the dryer attached and idle")
	return d
end

local function finish(d, want)
	run_until(function()
		local s = d.var.state
		return s == "done" or s == "failed" or s == "cancelled"
	end, 7200, "the end of the programme")
	expect_eq(d.var.state, want or "done", "end state (error: " .. tostring(d.var.error) .. ")")
end

-- The rules every test keeps. The driver sees the door at its next service
-- and its outputs go out at the one after: its commands may lag the door by
-- two periods. The wiring may not lag at all, and the plant's own safety
-- monitor must never see the heater powered over a still drum.
local function rules(d)
	always("the driver turns the heater and the drum off within two periods of the door opening", function()
		return d.plant.door_closed or not (d.out.heater or d.out.drum)
	end, { within = "2 periods" })
	always("no power to the heater with the door open (the door switch is in its supply)", function()
		return d.plant.door_closed or not d.plant.heater_on
	end)
	always("the heater only with the drum turning", function()
		return not d.out.heater or d.plant.drum_turning
	end, { within = "2 periods" })
	always("never an unsafe moment in the plant", function() return d.plant.unsafe_episodes == 0 end)
end

local function record_steps(d)
	local steps = {}
	always("(recording steps)", function()
		local s = d.var.step
		if s and s ~= "-" and steps[#steps] ~= s then steps[#steps + 1] = s end
		return true
	end)
	return steps
end

test("cotton at full length: warms up, dries at 70 C, cools, and the laundry comes out dry", function()
	local d = dryer { time_scale = 1 }
	rules(d)
	local steps = record_steps(d)
	d:input("start", "cotton")
	run_until(function() return d.var.step == "dry" end, 600, "the dry step")
	local dry_start = now()
	always("70 C held within 4 C while drying", function()
		return d.var.step ~= "dry" or math.abs(d.plant.temp_c - 70) < 4
	end)
	run_until(function() return d.var.step == "cool" end, 3600, "the cool step")
	expect_near(now() - dry_start, 50 * 60, 1, "seconds of drying")
	finish(d)
	expect_eq(table.concat(steps, ", "), "warm up, dry, cool", "steps")
	expect(d.plant.moisture_kg < 0.1, "dry laundry: " .. d.plant.moisture_kg .. " kg of water left of 2")
	expect(d.plant.temp_c < 40, "cooled laundry: " .. d.plant.temp_c .. " C")
	expect(d.plant.max_temp_c < 75, "never above 75 C: " .. d.plant.max_temp_c .. " C")
	expect(not d.plant.cutout_open, "the cut-out never tripped")
	eventually(function() return not (d.out.heater or d.out.drum) end, 0.2, "everything off at the end")
end)

test("delicate stays gentle: never above 53 C", function()
	local d = dryer { time_scale = 0.1 }
	rules(d)
	local steps = record_steps(d)
	d:input("start", "delicate")
	finish(d)
	expect_eq(table.concat(steps, ", "), "warm up, dry, cool", "steps")
	expect(d.plant.max_temp_c < 53, "the hottest: " .. d.plant.max_temp_c .. " C")
	expect(d.plant.heater_s > 60, "the heater ran: " .. d.plant.heater_s .. " s")
end)

for _, at in ipairs { "warm up", "dry", "cool" } do
	test("door opened during " .. at .. ": no power at once, the driver's off within two periods, resumes", function()
		local d = dryer()
		rules(d)
		d:input("start", "cotton")
		run_until(function() return d.var.step == at end, 600, "the " .. at .. " step")
		run_for(2)
		d:open_door()
		expect(not d.plant.heater_on, "the heater without power the moment the door opens")
		eventually(function() return not (d.out.heater or d.out.drum) end, 0.2, "the driver's heater and drum off")
		run_until(function() return d.var.state == "paused" end, 1, "the programme paused")
		expect_eq(d.var.paused_by, "door open", "paused by")
		expect_eq(d.var.door_open, true, "the door published open")
		run_for(20)
		expect(d.plant.drum_rpm < 1, "the drum still behind the open door")
		d:close_door()
		run_until(function() return d.var.state == "running" end, 1, "the programme resumed")
		finish(d)
	end)
end

test("start refused while the door is open", function()
	local d = dryer()
	d:open_door()
	run_for(0.5)
	local ok, reply = d:try_input("start", "cotton")
	expect(not ok, "a start with the door open refused")
	expect(tostring(reply):find("close the door first", 1, true), "the refusal says why: " .. tostring(reply))
	expect_eq(d.var.state, "idle", "state")
end)

test("cancel while drying: heat off at once, tumbled below 45 C, then all off", function()
	local d = dryer()
	rules(d)
	d:input("start", "cotton")
	run_until(function() return d.var.step == "dry" end, 600, "the dry step")
	d:input("cancel")
	eventually(function() return not d.out.heater end, 0.2, "the heater off")
	expect(d.out.drum, "the drum tumbling the hot laundry")
	run_until(function() return d.var.state == "cancelled" end, 900, "the cancel to complete")
	expect(d.plant.temp_c <= 46, "cooled to 45 C before stopping: " .. d.plant.temp_c .. " C")
	eventually(function() return not (d.out.heater or d.out.drum) end, 0.2, "everything off")
end)

test("a broken belt: the heater off before the drum is still, the programme cancelled with an event", function()
	local d = dryer()
	rules(d)
	d:input("start", "cotton")
	run_until(function() return d.var.step == "dry" end, 600, "the dry step")
	d:set("belt_broken", 1)
	run_until(function() return not d.plant.drum_turning end, 5, "the drum slowing down")
	eventually(function() return not d.out.heater end, 0.2, "the heater off")
	run_until(function() return d.var.state == "cancelling" or d.var.state == "cancelled" end, 10, "the cancel")
	expect_event({ kind = "driver", text = "the drum does not turn" }, "the driver's event")
	finish(d, "cancelled")
end)

test("the thermal cut-out: a weak one trips, the heater loses its supply, the warm-up fails", function()
	local d = dryer { time_scale = 0.05, heat_timeout_s = 300 }
	rules(d)
	d:set("cutout_c", 60)
	d:input("start", "cotton")
	run_until(function() return d.plant.cutout_open end, 600, "the cut-out to trip")
	expect_eq(d.var.step, "warm up", "the step when the cut-out trips")
	expect(not d:try_set("reset_cutout"), "no reset while hot")
	run_for(2)
	expect_eq(d.var.target_c, 70, "the driver still asking for heat")
	expect(not d.plant.heater_on, "no power to the heater past an open cut-out")
	finish(d, "failed")
	expect_eq(d.var.error, "warm up: timed out after 300 s waiting for 70 C", "error")
	expect(d.plant.max_temp_c < 61, "the air never past the cut-out: " .. d.plant.max_temp_c .. " C")
	run_until(function() return d.plant.temp_c < 59 end, 1800, "the dryer to cool")
	d:set("reset_cutout")
	expect(not d.plant.cutout_open, "the cut-out reset once cool")
end)

for _, opened in ipairs { false, true } do
	local what = opened and "the door opened meanwhile: cancelled, saying why" or "the programme resumes"
	test("the host restarted while drying, " .. what, function()
		local d = dryer()
		rules(d)
		d:input("start", "cotton")
		run_until(function() return d.var.step == "dry" end, 600, "the dry step")
		crash_host()
		eventually(function() return not (d.out.heater or d.out.drum) end, 1, "the board's watchdog: all off")
		if opened then d:open_door() end
		start_host()
		run_until(function() return d.var and d.var.state ~= nil and d.var.state ~= "idle" end, 10, "the restart")
		if opened then
			expect_event({ kind = "driver", text = "the door is open" }, "the cancel says why")
			run_until(function() return d.var.paused_by == "door open" end, 1, "the cancel's cool-down held by the door")
			d:close_door()
			finish(d, "cancelled")
		else
			expect_eq(d.var.step, "dry", "the step after the restart")
			finish(d)
		end
	end)
end
