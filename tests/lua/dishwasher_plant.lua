-- dishwasher_plant: the simulated dishwasher of firmware/plants/dishwasher.c
-- in Lua, with the board interface of washer_plant (sense, actuate, step),
-- for driving the shipped dishwasher driver in virtual time
-- (tests/lua/test_recover.lua). I/O map: docs/BOARD.md "Dishwasher".

local dishwasher_plant = {}

local TANK_MAX_L, LEVEL_SWITCH_L, DRAIN_LPS = 6, 3, 0.5

-- dishwasher_plant.new{fill_rate_lps = 0.25} -> plant
function dishwasher_plant.new(spec)
	spec = spec or {}
	local p = { water_l = 0, door_closed = true, fill_rate_lps = spec.fill_rate_lps or 0.25,
		applied = { digital = {}, pwm = 0 }, t = 0 }

	function p.set_door(closed) p.door_closed = closed; return true end

	function p.actuate(outputs)
		local digital = {}
		for i = 1, 7 do digital[i] = outputs and outputs.digital and outputs.digital[i] == true or false end
		p.applied = { digital = digital, pwm = 0 }
	end

	function p.step(dt)
		local d = p.applied.digital
		if d[1] then p.water_l = p.water_l + p.fill_rate_lps * dt end
		if d[3] then p.water_l = p.water_l - DRAIN_LPS * dt end
		p.water_l = math.max(0, math.min(TANK_MAX_L, p.water_l))
		p.t = p.t + dt
	end

	function p.sense()
		return {
			digital = { p.door_closed, p.water_l >= LEVEL_SWITCH_L, false, false, false, false, false, false },
			analog = { math.floor(p.water_l * 100 + 0.5), 0 },
			encoder = 0,
			time = p.t,
		}
	end

	return p
end

return dishwasher_plant
