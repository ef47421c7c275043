-- A one-board driver whose input "fail" raises an error, for what the
-- host and vmac test do with a driver that fails in input()
-- (tests/vtest/cases/inputs.lua); "set" turns do0 on, "refuse" is
-- refused.
local driver = {
	name = "fragile", version = "1",
	io = { lamp = "do0" },
	commands = { set = {}, refuse = {}, fail = {} },
}

local lamp = false

function driver.tick(dev)
	dev.out.lamp = lamp
end

function driver.input(_, name)
	if name == "fail" then
		error("failing on purpose")
	end
	if name == "set" then
		lamp = true
		return true
	end
	return nil, "not now"
end

return driver
