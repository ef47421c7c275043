-- plants/dryer.lua: the tumble dryer behind board dryer-1, in Lua
-- (docs/BOARD.md, "Plant models in Lua"). It runs in `vmac test` and behind
-- `vmac-board --plant-file`. The wiring, as on a real dryer: the door switch
-- is in series with the supply of the heater and of the drum motor (an open
-- door powers neither, whatever the driver says), and a thermal cut-out in
-- series with the heater opens above cutout_c and stays open until someone
-- resets it by hand once the dryer has cooled. What it watches: the heater
-- powered over a still drum (it scorches the laundry by the element), and
-- the air hotter than any cut-out allows.

local AMBIENT_C = 20
local HEAT_C_PER_S = 0.6     -- the heater warming the air through a tumbling load
local HOT_SPOT_C_PER_S = 2.5 -- the same heater over a still drum: no air flow past the sensor
local LOSS_PER_S = 0.004     -- heat lost to the room, per degree above it
local EVAP_KG_PER_S_C = 3e-5 -- water leaving the laundry per degree above 30 C, wet laundry tumbling
local EVAP_COOL_C_PER_KG = 300 -- evaporating water cools the air
local DRUM_RPM = 50          -- the drum's speed with its motor powered
local SPIN_UP_S, COAST_S = 1, 2 -- time constants of the drum speeding up and coasting down
local TURNING_RPM = 30       -- the rotation sensor reads on above this
local STILL_RPM = 10         -- below this the drum counts as still
local CUTOUT_RESET_C = 60    -- the cut-out resets only below this
local OVERHEAT_C = 135       -- hotter than any cut-out should ever let the air get

return {
	name = "dryer",
	io = {
		heater = "do0",
		drum = "do1",
		door_closed = "di0",
		start_button = "di1",
		cancel_button = "di2",
		drum_turning = "di3",
		temp_c = { "ai0", scale = 0.05, offset = -20 }, -- -20..184.75 C
	},
	state = {
		temp_c = AMBIENT_C,
		door_closed = true,
		start_button = false,
		cancel_button = false,
		drum_turning = false,
		drum_rpm = 0,
		load_kg = 4,          -- dry laundry
		moisture_kg = 2,      -- water in it (spun at 1000 RPM: half its weight)
		cutout_c = 120,       -- the cut-out's rating (b:set("cutout_c", 60): a weak one)
		cutout_open = false,  -- tripped: the heater has no supply until reset
		belt_broken = false,  -- a fault: the motor runs, the drum does not
		heater_on = false,    -- the heater is powered (its supply closed and switched on)
		heater_s = 0,         -- seconds the heater has been powered
		max_temp_c = AMBIENT_C, -- the hottest the air has been
	},
	step = function(p, dt, out)
		-- The wiring: no supply with the door open; the heater's through the cut-out too.
		local motor = out.drum and p.door_closed
		p.heater_on = out.heater and p.door_closed and not p.cutout_open
		local turning_to = (motor and not p.belt_broken) and DRUM_RPM or 0
		local tau = turning_to > 0 and SPIN_UP_S or COAST_S
		p.drum_rpm = turning_to + (p.drum_rpm - turning_to) * math.exp(-dt / tau)
		p.drum_turning = p.drum_rpm > TURNING_RPM
		local still = p.drum_rpm < STILL_RPM

		local heat = 0
		if p.heater_on then
			heat = still and HOT_SPOT_C_PER_S or HEAT_C_PER_S
			p.heater_s = p.heater_s + dt
		end
		local wet = p.moisture_kg / (p.moisture_kg + 0.3)
		local evap = EVAP_KG_PER_S_C * math.max(0, p.temp_c - 30) * wet * (still and 0.2 or 1)
		p.moisture_kg = math.max(0, p.moisture_kg - evap * dt)
		p.temp_c = p.temp_c + dt * (heat - LOSS_PER_S * (p.temp_c - AMBIENT_C) - evap * EVAP_COOL_C_PER_KG)
		p.max_temp_c = math.max(p.max_temp_c, p.temp_c)
		if p.temp_c >= p.cutout_c and not p.cutout_open then
			p.cutout_open = true -- the latch: open until reset_cutout
		end

		if p.heater_on and still then
			return string.format("heater powered with the drum still (%.0f RPM)", p.drum_rpm)
		elseif p.temp_c > OVERHEAT_C then
			return string.format("air at %.0f C, over %d C", p.temp_c, OVERHEAT_C)
		end
	end,
	actions = {
		door = function(p, v)
			if v ~= 0 and v ~= 1 then return false, "door takes 0 (open) or 1 (closed)" end
			p.door_closed = v == 1
			if not p.door_closed then
				p.heater_on = false -- the door switch breaks the supply the moment it opens
			end
		end,
		reset_cutout = function(p)
			if p.temp_c >= CUTOUT_RESET_C then
				return false, string.format("the cut-out resets below %d C; the air is at %.0f C", CUTOUT_RESET_C,
					p.temp_c)
			end
			p.cutout_open = false
		end,
		start = "start_button",
		cancel = "cancel_button",
	},
}
