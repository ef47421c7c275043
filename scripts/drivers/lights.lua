-- Lights: the kitchen and dining lights, the TV and the garbage disposal on
-- relays. The wall switches are toggle switches: every change of a switch's
-- position flips its light (switch 1: kitchen, switch 2: dining). An
-- operator may set any of the four from the UI or the API; the state is
-- published. A hot reload keeps every relay as it was; after a restart,
-- recover switches back on what was on at the host's checkpoint. Board I/O:
-- docs/BOARD.md, "Lights".

local driver = {
	name = "lights",
	version = "1.2.0",
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
		kitchen = { set = true, device_class = "switch", label = "Kitchen light" },
		dining = { set = true, device_class = "switch", label = "Dining light" },
		tv = { set = true, device_class = "switch", label = "TV" },
		disposal = { set = true, device_class = "switch", label = "Garbage disposal" },
	},
	commands = {
		all_off = { label = "All off" },
	},
	ui = { title = "Lights", icon = "light", plots = { { "kitchen", "dining", "tv", "disposal" } } },
}

local RELAYS = { "kitchen", "dining", "tv", "disposal" }
local SWITCHES = { "switch1", "switch2" }
-- The state, in dev.state for a hot reload: relay name -> on, and switch
-- name -> its position at the previous tick (nil before the first).
local relays = { kitchen = false, dining = false, tv = false, disposal = false }
local switches = {}

local function show(dev)
	for _, r in ipairs(RELAYS) do
		dev.vars[r] = relays[r]
	end
end

function driver.attach(dev)
	for _, r in ipairs(RELAYS) do
		relays[r] = false
	end
	dev.state.relays, dev.state.switches = relays, switches
	show(dev)
end

function driver.tick(dev, inputs)
	if switches.switch1 ~= nil and inputs.switch1 ~= switches.switch1 then
		relays.kitchen = not relays.kitchen
	end
	if switches.switch2 ~= nil and inputs.switch2 ~= switches.switch2 then
		relays.dining = not relays.dining
	end
	switches.switch1, switches.switch2 = inputs.switch1, inputs.switch2
	show(dev)
	for _, r in ipairs(RELAYS) do
		dev.out[r] = relays[r]
	end
end

function driver.input(dev, name, value)
	if name == "all_off" then
		for _, r in ipairs(RELAYS) do
			relays[r] = false
		end
	else
		relays[name] = value == true
	end
	show(dev)
	return true
end

-- Hot reload (docs/DRIVERS.md): the relays as the old version had them
-- (from dev.out, its outputs, when it kept no dev.state: 1.0.0), and the
-- switch positions, so a flip between the two versions' ticks still counts.
function driver.migrate(dev, old)
	local old_relays = type(old.relays) == "table" and old.relays or dev.out
	for _, r in ipairs(RELAYS) do
		relays[r] = old_relays[r] == true
	end
	if type(old.switches) == "table" then
		for _, name in ipairs(SWITCHES) do
			if type(old.switches[name]) == "boolean" then
				switches[name] = old.switches[name]
			end
		end
	end
	show(dev)
end

-- Recovery after a restart (docs/DRIVERS.md), after attach and before the
-- first tick: the lights and the TV that were on at the checkpoint go on
-- again, at the first tick. Not the garbage disposal: a motor that starts
-- by itself, maybe minutes later, could catch a hand; an event says it was
-- left off. The switch positions are not taken over: a switch may have
-- moved while the host was away, and the first tick reads where they are.
local RECOVERED = { "kitchen", "dining", "tv" }

function driver.recover(dev, saved)
	local old = type(saved.state) == "table" and saved.state.relays
	if type(old) ~= "table" then
		return
	end
	for _, r in ipairs(RECOVERED) do
		relays[r] = old[r] == true
	end
	if old.disposal == true then
		dev:event("recovery: the garbage disposal was on; left off")
	end
	show(dev)
end

return driver
