-- washer_plant: the simulated washer of firmware/plants/washer.c in Lua,
-- with the bus's one-period output delay, for driving an example washer
-- driver in virtual time (tests/lua/test_washer_example.lua). Physics and
-- I/O map: docs/BOARD.md "Washer".

local washer_plant = {}

local AMBIENT_C, HOT_C, COLD_C, COOLING_TAU_S = 20, 60, 15, 600
local DRAIN_LPS, TUB_MAX_L, EMPTY_BELOW_L = 1.0, 40, 0.5
local COUNTS_PER_REV = 360

local function bit_on(digital, index) return digital and digital[index] == true end

local function counts(value)
	local c = math.floor(value + 0.5)
	if c < 0 then return 0 elseif c > 4095 then return 4095 end
	return c
end

-- washer_plant.new{load_kg=3, fill_rate_lps=0.5} -> plant
function washer_plant.new(spec)
	spec = spec or {}
	local p = {
		water_l = 0, water_c = AMBIENT_C, rpm = 0, position = 0,
		load_kg = spec.load_kg or 3, fill_rate_lps = spec.fill_rate_lps or 0.5,
		door_closed = true, door_locked = false,
		applied = { digital = {}, pwm = 0 },   -- the outputs the board drives now
		t = 0,
	}

	local function update_lock()
		p.door_locked = p.door_closed and bit_on(p.applied.digital, 4)
	end

	-- Operator action "door": false opens (refused while locked), true closes.
	-- Returns true, or false when refused.
	function p.set_door(closed)
		if not closed and p.door_locked then return false end
		p.door_closed = closed
		update_lock()
		return true
	end

	-- The board takes the outputs the host sent with this period's request.
	function p.actuate(outputs)
		local digital = {}
		for i = 1, 7 do digital[i] = outputs and outputs.digital and outputs.digital[i] == true or false end
		local pwm = outputs and outputs.pwm or 0
		pwm = pwm >= 0 and math.floor(pwm) or -math.floor(-pwm) -- truncated, as on the wire
		p.applied = { digital = digital, pwm = pwm }
		update_lock()
	end

	function p.step(dt)
		local out = p.applied
		-- drum: exact first-order step, encoder by the exact integral
		local enabled = bit_on(out.digital, 5)
		local pwm = math.max(-1000, math.min(1000, out.pwm))
		local drag = (enabled and 1.0 or 0.3) + 0.005 * p.water_l
		local inertia = 1.5 + 0.25 * p.load_kg + 0.05 * p.water_l
		local tau = inertia / drag
		local target = enabled and pwm / drag or 0
		local approach = 1 - math.exp(-dt / tau)
		local rpm_seconds = target * dt + (p.rpm - target) * tau * approach
		p.position = p.position + rpm_seconds / 60 * COUNTS_PER_REV
		p.rpm = p.rpm + (target - p.rpm) * approach
		if target == 0 and math.abs(p.rpm) < 1e-6 then p.rpm = 0 end
		-- water
		local hot = bit_on(out.digital, 1) and p.fill_rate_lps * dt or 0
		local cold = bit_on(out.digital, 2) and p.fill_rate_lps * dt or 0
		local total = p.water_l + hot + cold
		if total > 0 and hot + cold > 0 then
			p.water_c = (p.water_l * p.water_c + hot * HOT_C + cold * COLD_C) / total
		end
		p.water_l = total
		p.water_c = AMBIENT_C + (p.water_c - AMBIENT_C) * math.exp(-dt / COOLING_TAU_S)
		if bit_on(out.digital, 3) then p.water_l = p.water_l - DRAIN_LPS * dt end
		if p.water_l < 0 then p.water_l = 0 end
		if p.water_l > TUB_MAX_L then p.water_l = TUB_MAX_L end
		update_lock()
		p.t = p.t + dt
	end

	-- The board's reply, as the driver sees it (docs/DRIVERS.md).
	function p.sense()
		return {
			digital = { p.door_closed, p.door_locked, p.water_l < EMPTY_BELOW_L, false, false, false, false, false },
			analog = { counts(p.water_l * 100), counts(p.water_c * 40) },
			encoder = math.floor(p.position),
			time = p.t,
		}
	end

	return p
end

-- A bus in virtual time: every period the driver ticks on the board's
-- reply, and what it returns reaches the board with the next request.
-- bus:run(seconds, each) calls each(t) after every tick.
function washer_plant.bus(driver, plant, period_s)
	local bus = { period_s = period_s or 0.03, pending = nil }
	function bus.tick()
		plant.actuate(bus.pending)
		bus.pending = driver.tick(plant.sense())
		plant.step(bus.period_s)
	end
	function bus.run(seconds, each)
		for _ = 1, math.floor(seconds / bus.period_s + 0.5) do
			bus.tick()
			if each and each(plant.t) then return true end
		end
		return false
	end
	return bus
end

return washer_plant
