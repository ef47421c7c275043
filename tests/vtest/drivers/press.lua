-- A press of two boards (major 7): each drives one clamp of a pair that must
-- close at one instant. Toggles both clamps every tick, so each period
-- has an output change on both boards (tests/vtest/cases/timed.lua).
local driver = {
	name = "press", version = "1",
	io = { clamp_l = { "do0", board = 0 }, clamp_r = { "do0", board = 1 } },
}

function driver.tick(dev, inputs)
	local on = not dev.out.clamp_l
	dev.out.clamp_l = on
	dev.out.clamp_r = on
end

return driver
