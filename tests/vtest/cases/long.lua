-- A test that waits longer in virtual time than --time-limit allows.
test("waits a day", function()
	board { name = "lights-1", plant = "lights" }
	run_for(24 * 3600)
end)
