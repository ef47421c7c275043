-- always() with a grace: the dishwasher's door interlock. Opening the door
-- stops everything within a service or two of the driver, never at the
-- very moment the plant's door opens.
local function washing()
	local d = board { name = "dishwasher-1", plant = "dishwasher", params = { time_scale = 0.05 } }
	run_until(function() return d.var.state == "idle" end, 5, "the dishwasher idle")
	d:input("start", "normal")
	run_until(function() return d.var.step == "wash" end, 600, "the wash step")
	return d
end

local function all_off(d) return not (d.out.fill_valve or d.out.wash_motor or d.out.drain_pump) end

test("off within 2 periods of the door opening", function()
	local d = washing()
	always("nothing runs with the door open", function() return d.plant.door_closed or all_off(d) end,
		{ within = "2 periods" })
	d:open_door()
	run_for(1)
end)

test("off at the moment the door opens", function()
	local d = washing()
	always("nothing runs with the door open", function() return d.plant.door_closed or all_off(d) end)
	d:open_door()
	run_for(1)
end)

test("off within 1 ms of the door opening", function()
	local d = washing()
	always("nothing runs with the door open", function() return d.plant.door_closed or all_off(d) end,
		{ within = 0.001 })
	d:open_door()
	run_for(1)
end)

test("a grace does not excuse a condition that stays false", function()
	local d = washing()
	always("the door stays closed", function() return d.plant.door_closed end, { within = 0.5 })
	d:open_door()
	run_for(2)
end)
