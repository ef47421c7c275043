-- The generic driver (scripts/drivers/generic.lua) against the generic
-- board: every input published as a bit string, every output held off.
-- Run: build/bin/vmac test tests/drivers/generic_test.lua (docs/TESTING.md)

local function generic()
	local g = board { name = "io-1", plant = "generic" }
	run_until(function() return g.var.inputs ~= nil end, 5, "the generic board attached")
	always("every output held off", function()
		return not (g.out.do0 or g.out.do1 or g.out.do2 or g.out.do3 or g.out.do4 or g.out.do5 or g.out.do6)
			and g.out.pwm == 0
	end)
	return g
end

test("the digital inputs are published as a bit string, input 0 first", function()
	local g = generic()
	expect_eq(g.var.inputs, "00000000", "inputs at rest")
	g:set("di0", 1)
	g:set("di6", 1)
	run_until(function() return g.var.inputs == "10000010" end, 0.2, "inputs 0 and 6 published")
	g:release("di0")
	run_until(function() return g.var.inputs == "00000010" end, 0.2, "input 0 released")
end)

test("the analog inputs and the encoder reach the driver's names", function()
	local g = generic()
	g:set("ai1", 2048)
	g:set("encoder", -5)
	run_for(0.1)
	expect(g.io.ai1 > 0, "ai1 read above zero, got " .. tostring(g.io.ai1))
	expect_eq(g.io.encoder, -5, "encoder")
end)

test("a generic board that is unplugged is dropped and comes back when plugged in", function()
	local g = generic()
	g:unplug()
	run_until(function() return g.state == "errant" end, 1, "the board dropped")
	expect_event({ kind = "dropped", device = "io-1" }, "a drop event")
	g:replug()
	run_until(function() return g.state == "running" end, 10, "the board attached again")
end)
