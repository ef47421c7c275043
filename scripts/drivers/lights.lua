-- Lights driver: the wall switches are toggle switches; every change of a
-- switch's position flips its light (switch 1: kitchen, switch 2: dining).
-- TV and disposal relays stay off until operator input arrives (a later API).
-- Board I/O: docs/BOARD.md, "lights".

local KITCHEN, DINING, TV, DISPOSAL = 1, 2, 3, 4

local lights = { false, false, false, false }
local last_switch = nil -- positions seen at the previous tick

local driver = {}

function driver.tick(inputs)
	local switch = { inputs.digital[1], inputs.digital[2] }
	if last_switch then
		if switch[1] ~= last_switch[1] then lights[KITCHEN] = not lights[KITCHEN] end
		if switch[2] ~= last_switch[2] then lights[DINING] = not lights[DINING] end
	end
	last_switch = switch
	return { digital = { lights[KITCHEN], lights[DINING], lights[TV], lights[DISPOSAL] } }
end

return driver
