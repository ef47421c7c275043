-- pid: a PID controller for drivers' feedback loops (docs/STDLIB.md "pid"),
-- e.g. the washer drum's velocity loop. Derivative on the measurement (a
-- setpoint step gives no derivative kick), an integral kept in output units
-- and limited, anti-windup by conditional integration (the integral never
-- grows past what the output can use), and a clamped output.
-- The caller passes dt in seconds; nothing here reads a clock.

local type, error, huge = type, error, math.huge

local pid = {}

local Pid = {}
Pid.__index = Pid

local function is_number(x)
	return type(x) == "number" and x == x
end

local function option(spec, key, default)
	local value = spec[key]
	if value == nil then
		return default
	end
	if not is_number(value) then
		error("pid.new: " .. key .. " must be a number", 3)
	end
	return value
end

-- pid.new{kp=, ki=0, kd=0, out_min=-inf, out_max=inf, i_min=out_min,
-- i_max=out_max, d_filter_s=0} -> controller. kp, ki, kd are gains in output
-- units per unit of error (per second for ki, times seconds for kd).
function pid.new(spec)
	if type(spec) ~= "table" then
		error("pid.new: expects a table of gains and limits, e.g. pid.new{kp = 2, ki = 1}", 2)
	end
	if spec.kp == nil then
		error("pid.new: kp is required (a number)", 2)
	end
	local self = setmetatable({
		kp = option(spec, "kp", 0),
		ki = option(spec, "ki", 0),
		kd = option(spec, "kd", 0),
		out_min = option(spec, "out_min", -huge),
		out_max = option(spec, "out_max", huge),
		d_filter_s = option(spec, "d_filter_s", 0),
	}, Pid)
	self.i_min = option(spec, "i_min", self.out_min)
	self.i_max = option(spec, "i_max", self.out_max)
	if self.out_min >= self.out_max then
		error("pid.new: out_min must be less than out_max", 2)
	end
	if self.i_min > self.i_max then
		error("pid.new: i_min must not be greater than i_max", 2)
	end
	if self.d_filter_s < 0 then
		error("pid.new: d_filter_s must be >= 0 (seconds)", 2)
	end
	self:reset()
	return self
end

-- Forget the past: integral, last measurement, derivative filter, output.
function Pid:reset()
	self.i_term = 0
	self.p_term = 0
	self.d_term = 0
	self.output = 0
	self.last_measurement = nil
end

-- update(setpoint, measurement, dt) -> output in [out_min, out_max].
-- dt is the time since the previous update in seconds; dt == 0 returns the
-- previous output and changes nothing.
function Pid:update(setpoint, measurement, dt)
	if not is_number(setpoint) then
		error("pid:update: setpoint must be a number (not NaN)", 2)
	end
	if not is_number(measurement) then
		error("pid:update: measurement must be a number (not NaN)", 2)
	end
	if not is_number(dt) or dt < 0 then
		error("pid:update: dt must be a number >= 0 (seconds)", 2)
	end
	if dt == 0 then
		return self.output
	end

	local err = setpoint - measurement
	local p = self.kp * err

	-- Derivative of the measurement, not of the error: moving the setpoint
	-- does not kick the output. The first update has no previous sample.
	local d = 0
	local last = self.last_measurement
	if last ~= nil then
		d = -self.kd * (measurement - last) / dt
		if self.d_filter_s > 0 then
			d = self.d_term + (d - self.d_term) * dt / (self.d_filter_s + dt)
		end
	end
	self.last_measurement = measurement

	-- Conditional integration: integrate toward the error only as far as
	-- the output has room. A saturated output in the direction of the error
	-- leaves the integral as it is, so it does not wind up.
	local i = self.i_term
	local step = self.ki * err * dt
	if step > 0 then
		local room = self.out_max - p - d
		if i < room then
			i = i + step
			if i > room then i = room end
		end
	elseif step < 0 then
		local room = self.out_min - p - d
		if i > room then
			i = i + step
			if i < room then i = room end
		end
	end
	if i > self.i_max then i = self.i_max elseif i < self.i_min then i = self.i_min end

	local out = p + i + d
	if out > self.out_max then out = self.out_max elseif out < self.out_min then out = self.out_min end

	self.p_term, self.i_term, self.d_term, self.output = p, i, d, out
	return out
end

return pid
