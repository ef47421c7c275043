-- A machine of two boards (major 8) that publishes how long after its
-- tick's time any board's inputs were sampled (dev.boards[i].t less
-- inputs.time, the most seen: none should come after) and how many ticks
-- it ran (tests/vtest/cases/timed.lua).
local driver = {
	name = "sampled", version = "1",
	io = { a = { "do0", board = 0 }, b = { "do0", board = 1 } },
	variables = { after_us = {}, ticks = {} },
}

function driver.attach(dev)
	dev.vars.after_us, dev.vars.ticks = -1e9, 0
end

function driver.tick(dev, inputs)
	dev.vars.ticks = dev.vars.ticks + 1
	for _, b in ipairs(dev.boards) do
		dev.vars.after_us = math.max(dev.vars.after_us, (b.t - inputs.time) * 1e6)
	end
end

return driver
