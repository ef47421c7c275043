-- Lights: the kitchen and dining lights, the TV and the garbage disposal on
-- relays. The wall switches are toggle switches: every change of a switch's
-- position flips its light (switch 1: kitchen, switch 2: dining). An
-- operator may set any of the four from the UI or the API; the state is
-- published. Board I/O: docs/BOARD.md, "Lights".

local driver = {
	name = "lights",
	version = "1.0.0",
	level = 4, -- 16 ms with 1 ms slots: a switch feels instant
	description = "kitchen and dining lights, TV and disposal relays, two wall switches",
	io = {
		switch1 = "di0",
		switch2 = "di1",
		kitchen = "do0",
		dining = "do1",
		tv = "do2",
		disposal = "do3",
	},
	variables = {
		kitchen = { set = true, label = "Kitchen light" },
		dining = { set = true, label = "Dining light" },
		tv = { set = true, label = "TV" },
		disposal = { set = true, label = "Garbage disposal" },
	},
	commands = {
		all_off = { label = "All off" },
	},
	ui = { title = "Lights", icon = "light", plots = { { "kitchen", "dining", "tv", "disposal" } } },
}

local RELAYS = { "kitchen", "dining", "tv", "disposal" }
local last1, last2 -- switch positions at the previous tick

function driver.attach(dev)
	for _, r in ipairs(RELAYS) do
		dev.vars[r] = false
	end
end

function driver.tick(dev, inputs)
	if last1 ~= nil and inputs.switch1 ~= last1 then
		dev.vars.kitchen = not dev.vars.kitchen
	end
	if last2 ~= nil and inputs.switch2 ~= last2 then
		dev.vars.dining = not dev.vars.dining
	end
	last1, last2 = inputs.switch1, inputs.switch2
	for _, r in ipairs(RELAYS) do
		dev.out[r] = dev.vars[r]
	end
end

function driver.input(dev, name, value)
	if name == "all_off" then
		for _, r in ipairs(RELAYS) do
			dev.vars[r] = false
		end
	else
		dev.vars[name] = value == true
	end
	return true
end

return driver
