-- every(dt, fn): test-side behaviour on the clock (a person at the door),
-- its times, :stop(), and its mistakes. The last two tests fail on purpose.
test("every calls fn at its times while the clock runs", function()
	local times = {}
	local ticker = every(0.25, function(t) times[#times + 1] = t end)
	run_for(1)
	expect_eq(#times, 4, "calls in the first second")
	for i, t in ipairs(times) do expect_near(t, 0.25 * i, 1e-9, "call " .. i .. "'s time") end
	ticker:stop()
	run_for(1)
	expect_eq(#times, 4, "calls after stop()")
end)

test("a person opens and closes the door every 5 s", function()
	local d = board { name = "dishwasher-1", plant = "dishwasher", params = { time_scale = 0.05 } }
	run_until(function() return d.var.state == "idle" end, 5, "the dishwasher idle")
	d:input("start", "normal")
	run_until(function() return d.var.step == "wash" end, 600, "the wash step")
	always("nothing runs with the door open", function()
		return d.plant.door_closed or not (d.out.fill_valve or d.out.wash_motor or d.out.drain_pump)
	end, { within = "2 periods" })
	local openings = 0
	every(5, function()
		if d.plant.door_closed then
			d:open_door()
			openings = openings + 1
		else
			d:close_door()
		end
	end)
	run_for(30)
	expect_eq(openings, 3, "door openings in 30 s")
end)

test("an error in fn fails at fn's line", function()
	every(0.5, function(t)
		if t > 1.2 then error("the person tripped") end
	end)
	run_for(2)
end)

test("every needs seconds > 0", function()
	every(0, function() end)
end)
