-- The dishwasher driver (scripts/drivers/dishwasher.lua) and its programmes
-- (scripts/cycles/dishwasher/), against the dishwasher plant in virtual time.
-- Run: build/bin/vmac test tests/drivers/dishwasher_test.lua (docs/TESTING.md)

local function dishwasher(time_scale)
	local d = board { name = "dishwasher-1", plant = "dishwasher", params = { time_scale = time_scale or 0.05 } }
	run_until(function() return d.var.state == "idle" end, 5, "the dishwasher attached and idle")
	return d
end

local function all_off(d)
	return not (d.out.fill_valve or d.out.wash_motor or d.out.drain_pump)
end

local function finish(d)
	run_until(function()
		local s = d.var.state
		return s == "done" or s == "failed" or s == "cancelled"
	end, 3600, "the end of the programme")
	expect_eq(d.var.state, "done", "end state (error: " .. tostring(d.var.error) .. ")")
end

local function rules(d)
	always("the wash motor runs only with water at the level switch", function()
		return not d.out.wash_motor or d.inp.level_switch
	end)
	always("nothing runs with the door open", function() return d.plant.door_closed or all_off(d) end)
	always("the fill valve and the drain pump are never open together", function()
		return not (d.out.fill_valve and d.out.drain_pump)
	end)
end

local PROGRAMMES = {
	{ "normal", steps = "fill pre-rinse drain fill wash drain fill rinse drain fill rinse drain dry" },
	{ "rinse", steps = "fill rinse drain" },
}

for _, p in ipairs(PROGRAMMES) do
	test(p[1] .. " programme: every step in order, water only when washing, empty and off at the end", function()
		local d = dishwasher(0.05)
		rules(d)
		local steps = {}
		always("(recording steps)", function()
			local s = d.var.step
			if s and s ~= "-" and steps[#steps] ~= s then steps[#steps + 1] = s end
			return true
		end)
		d:input("start", p[1])
		finish(d)
		expect_eq(table.concat(steps, " "), p.steps, "steps")
		eventually(function() return all_off(d) end, 0.2, "every output off after the cycle")
		expect(d.plant.water_l < 0.1, "an empty tank after the cycle")
		expect(d.plant.wash_time_s > 0, "the wash motor to have run with water")
	end)
end

for _, at in ipairs { "fill", "wash", "drain" } do
	test("door opened during " .. at .. ": all off at once, pause, resume on closing, finish", function()
		local d = dishwasher(0.05)
		d:input("start", "normal")
		run_until(function() return d.var.step == at end, 600, "the " .. at .. " step")
		run_for(1)
		d:open_door()
		eventually(function() return all_off(d) end, 0.1, "every output off")
		run_until(function() return d.var.state == "paused" end, 1, "the cycle paused")
		expect_eq(d.var.paused_by, "door open", "paused by")
		always("nothing runs while the door is open", function() return d.plant.door_closed or all_off(d) end)
		run_for(30)
		d:close_door()
		run_until(function() return d.var.state == "running" end, 2, "the cycle resumed")
		finish(d)
	end)
end

test("cancel during the wash drains the tank and ends cancelled", function()
	local d = dishwasher(0.05)
	d:input("start", "normal")
	run_until(function() return d.var.step == "wash" end, 600, "the wash step")
	d:input("cancel")
	run_until(function() return d.var.state == "cancelled" end, 300, "the cancel to complete")
	expect(d.plant.water_l < 0.1, "the tank drained")
	eventually(function() return all_off(d) end, 0.2, "every output off")
end)

test("the dishwasher board dropping out mid-cycle: dropped, outputs off, the others go on", function()
	local k = kitchen { params = { dishwasher = { time_scale = 0.05 } } }
	local d, w = k.dishwasher, k.washer
	run_until(function() return d.var.state == "idle" and w.var.state == "idle" end, 5, "the kitchen attached")
	d:input("start", "normal")
	run_until(function() return d.var.step == "fill" end, 10, "the fill step")
	d:unplug()
	run_until(function() return d.state == "errant" end, 1, "the host to drop the dishwasher")
	run_until(function() return all_off(d) end, 1, "the board's watchdog turning its outputs off")
	expect_eq(w.device.misses, 0, "misses of the washer")
	w:input("start", "quick")
	run_until(function() return w.var.step == "fill" end, 5, "the washer starting its cycle")
end)
