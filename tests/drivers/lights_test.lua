-- The lights driver (scripts/drivers/lights.lua) against the lights plant:
-- wall switches toggle, operator input sets, the state is published.
-- Run: build/bin/vmac test tests/drivers/lights_test.lua (docs/TESTING.md)

local function lights()
	local l = board { name = "lights-1", plant = "lights" }
	run_until(function() return l.var.kitchen == false end, 5, "the lights attached")
	return l
end

test("a wall switch toggles its light, whichever way it is flipped", function()
	local l = lights()
	always("the wall switches never switch the TV or the disposal", function()
		return not l.out.tv and not l.out.disposal
	end)
	l:set("toggle1")
	run_until(function() return l.out.kitchen end, 0.2, "the kitchen light on")
	expect_eq(l.var.kitchen, true, "published kitchen")
	l:set("toggle1")
	run_until(function() return not l.out.kitchen end, 0.2, "the kitchen light off")
	l:set("toggle2")
	run_until(function() return l.out.dining end, 0.2, "the dining light on")
	expect(not l.out.kitchen, "the kitchen light still off")
end)

test("operator input sets a relay, all_off clears them all", function()
	local l = lights()
	l:input("tv", true)
	l:input("disposal", true)
	run_until(function() return l.out.tv and l.out.disposal end, 0.2, "tv and disposal on")
	expect_eq(l.var.tv, true, "published tv")
	run_for(2)
	expect_near(l.plant.on_seconds2, 2, 0.1, "seconds the tv relay was on")
	l:input("all_off")
	run_until(function() return not (l.out.tv or l.out.disposal or l.out.kitchen or l.out.dining) end, 0.2,
		"every relay off")
end)

test("an unknown input is refused and changes nothing", function()
	local l = lights()
	local ok = l:try_input("sauna", true)
	expect(not ok, "the unknown name to be refused")
	run_for(0.1)
	expect(not l.out.kitchen, "nothing switched on")
end)

test("a lights board that loses the host turns every relay off", function()
	local l = lights()
	l:input("kitchen", true)
	run_until(function() return l.out.kitchen end, 0.2, "the kitchen light on")
	l:unplug()
	-- The board's watchdog (500 ms) ends its session; allow the margin of a
	-- late poll and of the last service before the cable was pulled.
	run_until(function() return not l.out.kitchen end, 2, "the board's watchdog turning the light off")
	l:replug()
	run_until(function() return l.var.kitchen == false end, 5, "the lights attached again, all off")
end)

test("stopping the host turns every board's outputs off", function()
	local k = kitchen {}
	run_until(function() return k.lights.state == "running" and k.washer.var.state == "idle" end, 5,
		"the kitchen attached")
	k.lights:input("kitchen", true)
	k.washer:input("start", "quick")
	run_until(function() return k.lights.out.kitchen and k.washer.out.cold_valve end, 5, "a light and a valve on")
	stop_host()
	run_for(0.5)
	expect(not k.lights.out.kitchen, "the light off")
	expect(not k.washer.out.cold_valve and not k.washer.out.door_lock, "the washer's outputs off")
end)

test("a slow lights driver within its period still switches, one period later", function()
	driver_cost("lights", 0.005) -- every call takes 5 ms of the 16 ms period
	local l = lights()
	l:set("toggle1")
	run_until(function() return l.out.kitchen end, 0.2, "the kitchen light on")
	expect_eq(l.state, "running", "the lights' state")
	expect_eq(l.device.driver_late, 0, "ticks counted late (every output was ready by the next service)")
end)

test("a lights driver past its period but within its budget is counted late, not failed", function()
	config { ["driver.lights.budget_us"] = 50000 } -- its limit: 50 ms, past the 16 ms period
	driver_cost("lights", 0.020) -- every tick's outputs ready a period and 4 ms after its reply
	local l = lights()
	l:set("toggle1")
	run_until(function() return l.out.kitchen end, 0.5, "the kitchen light on, late")
	run_for(0.5)
	expect_eq(l.state, "running", "the lights' state")
	-- Every service finds the tick asked for a period before still running
	-- (each waits for the one before it): some 31 in 0.5 s.
	local late = l.device.driver_late
	expect(late >= 25, "ticks counted late in 0.5 s of 20 ms ticks every 16 ms: " .. tostring(late))
end)

test("a lights driver slower than its period is failed by the host, and the board goes safe", function()
	local washer = board { name = "washer-1", plant = "washer" }
	driver_cost("lights", 0.040) -- 40 ms, past the 16 ms period
	local l = board { name = "lights-1", plant = "lights" }
	local stalled = { kind = "driver_error", device = "lights-1", text = "tick still running after" }
	run_until(function() return #events(stalled) > 0 end, 2, "the lights driver judged stalled")
	local e = expect_event(stalled)
	expect(e.text:find("stalled", 1, true), "the event says the driver stalled: " .. e.text)
	-- Judged as the host judges it: once past its limit (a slot or so), not ten limits on.
	local after, limit = e.text:match("still running after ([%d.]+) ms %(its limit ([%d.]+) ms%)")
	expect(after and tonumber(after) <= 2 * tonumber(limit), "judged within two limits: " .. e.text)
	run_until(function() return l.state ~= "running" end, 1, "the lights dropped")
	expect(not (l.out.kitchen or l.out.dining or l.out.tv or l.out.disposal), "every relay off")
	expect_eq(washer.state, "running", "the washer's state")
end)

test("a slow attach shows the lights attaching until it returns, then running", function()
	driver_cost("lights", 0.010) -- every call, attach() too, takes 10 ms
	local l = board { name = "lights-1", plant = "lights" }
	local seen = {}
	local e = every(0.0005, function()
		local state = l.state
		if seen[#seen] ~= state then
			seen[#seen + 1] = state
		end
		expect_eq(l.device and l.device.state or "absent", state, "vmac test's state and the status's")
	end)
	run_until(function() return l.state == "running" end, 1, "the lights running")
	run_for(0.002)
	e:stop()
	local path = table.concat(seen, " > ")
	expect(path:find("attaching > running", 1, true), "the lights attaching, then running: " .. path)
end)
