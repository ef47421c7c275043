-- ramp: a setpoint generator with a trapezoidal rate profile, for drivers
-- (docs/STDLIB.md "ramp"): moves a value toward a target with its rate of
-- change bounded by max_rate (cruise) and the change of that rate bounded by
-- accel (speeding up) and decel (slowing down); e.g. the washer drum from
-- 45 to 400 RPM at 50 RPM/s. Also ramp.profile, the phase times of one move.
-- The caller passes dt in seconds; nothing here reads a clock.

local type, error, huge = type, error, math.huge
local abs, floor, sqrt, min = math.abs, math.floor, math.sqrt, math.min

local ramp = {}

local Ramp = {}
Ramp.__index = Ramp

local function is_number(x)
	return type(x) == "number" and x == x
end

-- Reads accel, decel and max_rate from spec for the function named where;
-- level 3 blames the caller of that function.
local function limits(spec, where)
	if type(spec) ~= "table" then
		error(where .. ": expects a table, e.g. " .. where .. "{accel = 100, max_rate = 50}", 3)
	end
	local accel, decel, max_rate = spec.accel, spec.decel, spec.max_rate
	if not is_number(accel) or accel <= 0 then
		error(where .. ": accel must be a number > 0 (units/s^2; math.huge for none)", 3)
	end
	if decel == nil then
		decel = accel
	elseif not is_number(decel) or decel <= 0 then
		error(where .. ": decel must be a number > 0 (units/s^2; default accel)", 3)
	end
	if max_rate == nil then
		max_rate = huge
	elseif not is_number(max_rate) or max_rate <= 0 then
		error(where .. ": max_rate must be a number > 0 (units/s; default no limit)", 3)
	end
	return accel, decel, max_rate
end

-- ramp.new{accel=, decel=accel, max_rate=inf, value=0} -> generator at rest
-- at value.
function ramp.new(spec)
	local accel, decel, max_rate = limits(spec, "ramp.new")
	local value = spec.value
	if value == nil then
		value = 0
	elseif not is_number(value) then
		error("ramp.new: value must be a number (the starting value)", 2)
	end
	return setmetatable({
		accel = accel, decel = decel, max_rate = max_rate,
		value = value, rate = 0, target = value,
	}, Ramp)
end

-- Set the value, at rest (rate 0), e.g. to a measured speed after the
-- drive was off.
function Ramp:reset(value)
	if not is_number(value) then
		error("ramp:reset: value must be a number", 2)
	end
	self.value, self.rate, self.target = value, 0, value
end

-- True when the value is at the last target and at rest.
function Ramp:done()
	return self.value == self.target and self.rate == 0
end

-- The largest speed from which, moving distance >= 0 toward the target in
-- steps of dt and then slowing by decel*dt per step, the value stops exactly
-- on the target. Speed v = (m + f) * q with q = decel*dt covers, this step
-- and after, dt*q*(m*(m+1)/2 + f*(m+1)); solve that for the distance.
local function stopping_speed(distance, decel, dt)
	if decel == huge then
		return distance / dt
	end
	local q = decel * dt
	local e = distance / (q * dt)
	local m = floor((sqrt(1 + 8 * e) - 1) / 2)
	while (m + 1) * (m + 2) / 2 <= e do m = m + 1 end
	while m > 0 and m * (m + 1) / 2 > e do m = m - 1 end
	local f = (e - m * (m + 1) / 2) / (m + 1)
	if f > 1 then f = 1 end
	return (m + f) * q
end

-- update(target, dt) -> the value after dt seconds of moving toward target.
-- The target may change at any call; dt == 0 changes nothing.
function Ramp:update(target, dt)
	if not is_number(target) then
		error("ramp:update: target must be a number (not NaN)", 2)
	end
	if not is_number(dt) or dt < 0 then
		error("ramp:update: dt must be a number >= 0 (seconds)", 2)
	end
	self.target = target
	if dt == 0 then
		return self.value
	end
	local value, rate = self.value, self.rate
	local remaining = target - value
	if remaining == 0 and rate == 0 then
		return value
	end
	local direction = remaining >= 0 and 1 or -1
	local speed = rate * direction -- > 0: toward the target
	local new_speed
	if speed < 0 or remaining == 0 then
		-- Moving away from (or through) the target: brake toward rest first.
		local s = abs(speed) - self.decel * dt
		if s < 0 then s = 0 end
		new_speed = (speed < 0 and -s or s)
	else
		local limit = min(self.max_rate, stopping_speed(abs(remaining), self.decel, dt))
		new_speed = min(limit, speed + self.accel * dt)
		local slowest = speed - self.decel * dt -- braking harder is not allowed
		if new_speed < slowest then new_speed = slowest end
	end
	local new_rate = new_speed * direction
	local new_value = value + new_rate * dt
	-- Arrived within rounding: land exactly, so done() can become true.
	if remaining ~= 0 and abs(target - new_value) <= 1e-12 * (abs(target) + 1) then
		new_value = target
	end
	-- On landing the rate is at most decel*dt, so the next update may bring
	-- it to 0 within the limit.
	self.value, self.rate = new_value, new_rate
	return new_value
end

-- ramp.profile{accel=, decel=accel, max_rate=inf, from=, to=} -> the
-- continuous-time plan of a move from rest to rest: { accel_s, cruise_s,
-- decel_s, total_s, peak_rate } (seconds, and units/s). A move too short to
-- reach max_rate has cruise_s == 0 and peak_rate < max_rate.
function ramp.profile(spec)
	local accel, decel, max_rate = limits(spec, "ramp.profile")
	if not is_number(spec.from) or not is_number(spec.to) then
		error("ramp.profile: from and to must be numbers", 2)
	end
	local distance = abs(spec.to - spec.from)
	-- Distance needed to reach a rate v and stop again: v^2/2 (1/a + 1/d).
	local peak = max_rate
	local k = 1 / (2 * accel) + 1 / (2 * decel)
	if peak == huge or peak * peak * k > distance then
		peak = sqrt(distance / k)
	end
	local accel_s, decel_s = peak / accel, peak / decel
	local cruise_s = 0
	if peak > 0 then
		cruise_s = (distance - peak * peak * k) / peak
		if cruise_s < 0 then cruise_s = 0 end
	end
	return {
		accel_s = accel_s, cruise_s = cruise_s, decel_s = decel_s,
		total_s = accel_s + cruise_s + decel_s, peak_rate = peak,
	}
end

return ramp
