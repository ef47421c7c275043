-- The dryer's figure beside washer_hour.lua's, for `make bench`: one hour of
-- virtual time of the kitchen's dryer (examples/kitchen/, user content)
-- running cotton programmes back to back at full length against its plant
-- in Lua, with the door rule checked at every tick; what a Lua plant costs
-- next to the washer's plant in C. Not named *_test.lua: a measurement run
-- by tests/bench/bench.py, not a test of `make test`.
-- By hand: build/bin/vmac test --drivers examples/kitchen tests/bench/dryer_hour.lua
local HOUR = 3600

test("an hour of drying, the dryer alone", function()
	local d = board { name = "dryer-1", plant = "dryer" }
	run_until(function() return d.var.state == "idle" end, 5, "the dryer idle")
	always("no power to the heater with the door open", function()
		return d.plant.door_closed or not d.plant.heater_on
	end)
	local programmes = 0
	while now() < HOUR do
		d:input("start", "cotton")
		programmes = programmes + 1
		run_until(function() return d.var.state == "running" end, 1, "the programme running")
		run_until(function() return d.var.state == "done" or now() >= HOUR end, HOUR, "the programme's end")
	end
	expect(programmes >= 1, "at least one programme started")
	expect_eq(d.plant.unsafe_episodes, 0, "unsafe episodes")
	expect_eq(d.state, "running", "the dryer's state after an hour")
end)
