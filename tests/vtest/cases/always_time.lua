-- An always() that reads only the clock: it must be checked between frames
-- too (the lights board is served every 16 ms; the limit falls between).
test("the clock stays below 0.5 s", function()
	board { name = "lights-1", plant = "lights" }
	always("the clock below 0.5 s", function() return now() < 0.5 end)
	run_for(1)
end)
