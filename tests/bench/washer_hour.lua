-- The figure of issue 5 for `make bench`: one hour of virtual time of a
-- washer running normal programmes back to back at full length, with the
-- door rule checked at every tick; alone, and in the demo kitchen. Not
-- named *_test.lua: a measurement run by tests/bench/bench.py (it reads the
-- wall time of each test from --junit), not a test of `make test`.
-- By hand: build/bin/vmac test tests/bench/washer_hour.lua
local HOUR = 3600

local function an_hour_of_washing(w)
	run_until(function() return w.var.state == "idle" end, 5, "the washer idle")
	always("the drum turns only behind a locked door", function()
		return math.abs(w.plant.drum_rpm) < 3 or w.plant.door_locked
	end)
	local programmes = 0
	while now() < HOUR do
		w:input("start", "normal")
		programmes = programmes + 1
		run_until(function() return w.var.state == "running" end, 1, "the programme running")
		run_until(function() return w.var.state == "done" or now() >= HOUR end, HOUR, "the programme's end")
	end
	expect(programmes >= 1, "at least one programme started")
	expect_eq(w.state, "running", "the washer's state after an hour")
end

test("an hour of washing, the washer alone", function()
	an_hour_of_washing(board { name = "washer-1", plant = "washer" })
end)

test("an hour of washing in the kitchen", function()
	an_hour_of_washing(kitchen {}.washer)
end)
