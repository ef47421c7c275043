-- Generic driver: a board with raw I/O and no machine behind it yet. Every
-- channel has a name, every input is published, every output is held off.
-- A starting point for a driver of your own: copy it to your --drivers
-- folder under a new name (and change `name`). Board I/O: docs/BOARD.md.

local driver = {
	name = "generic",
	version = "1.0.0",
	description = "raw I/O, outputs held off",
	io = {
		di0 = "di0", di1 = "di1", di2 = "di2", di3 = "di3",
		di4 = "di4", di5 = "di5", di6 = "di6", di7 = "di7",
		ai0 = "ai0", ai1 = "ai1", encoder = "encoder",
		do0 = "do0", do1 = "do1", do2 = "do2", do3 = "do3", do4 = "do4", do5 = "do5", do6 = "do6",
		pwm = "pwm",
	},
	variables = {
		inputs = { update = "auto" },
	},
	ui = { title = "Generic board" },
}

local names = { "di0", "di1", "di2", "di3", "di4", "di5", "di6", "di7" }

function driver.tick(dev, inputs)
	-- The digital inputs as one string, e.g. "10000000" (input 0 first).
	local bits = ""
	for _, n in ipairs(names) do
		bits = bits .. (inputs[n] and "1" or "0")
	end
	dev.vars.inputs = bits
end

return driver
