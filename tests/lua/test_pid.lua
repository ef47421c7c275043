-- Tests of stdlib/pid.lua against a simulated washer drum: a first-order
-- motor, rpm' = (k*u - rpm) / tau, with the drive u applied one tick late
-- as on the bus, at the thesis washer's 33 Hz.

local T = require "testing"
local pid = require "pid"
local test = T.test

local DT = 0.03       -- s, one bus period
local TAU = 2.25      -- s, drum time constant with 3 kg of laundry (docs/BOARD.md)
local GAIN = 1.0      -- RPM per unit of drive (per-mille PWM)

-- A drum at rest. drum:step(u) advances DT seconds with the drive of the
-- previous tick and returns the speed (RPM).
local function new_drum()
	local decay = math.exp(-DT / TAU)
	local drum = { rpm = 0, pending_u = 0 }
	function drum:step(u)
		local applied = self.pending_u
		self.pending_u = u
		local target = GAIN * applied
		self.rpm = target + (self.rpm - target) * decay
		return self.rpm
	end
	return drum
end

-- Gains for the drum: the integral cancels the drum's lag (ki = kp / tau).
local function drum_pid(extra)
	local spec = { kp = 2, ki = 2 / TAU, kd = 0, out_min = -1000, out_max = 1000 }
	for k, v in pairs(extra or {}) do spec[k] = v end
	return pid.new(spec)
end

-- Runs the loop for seconds; calls watch(t, rpm, u) every tick. Returns rpm.
local function run(controller, drum, setpoint, seconds, watch, t0)
	local t = t0 or 0
	local rpm = drum.rpm
	for _ = 1, math.floor(seconds / DT + 0.5) do
		local u = controller:update(setpoint, rpm, DT)
		rpm = drum:step(u)
		t = t + DT
		if watch then watch(t, rpm, u) end
	end
	return rpm
end

test("drives the drum to 45 RPM (agitation) within 1 RPM in 10 s and holds it", function()
	local controller, drum = drum_pid(), new_drum()
	run(controller, drum, 45, 30, function(t, rpm, u)
		T.check(u >= -1000 and u <= 1000, "drive %.1f outside the output limits at t=%.2f s", u, t)
		if t >= 10 then T.near(rpm, 45, 1, "drum speed at t=%.2f s", t) end
	end)
end)

test("drives the drum to 400 RPM (spin) within 4 RPM in 10 s and holds it", function()
	local controller, drum = drum_pid(), new_drum()
	run(controller, drum, 400, 30, function(t, rpm)
		if t >= 10 then T.near(rpm, 400, 4, "drum speed at t=%.2f s", t) end
	end)
end)

test("follows a load change: a 20 % stronger drag is corrected within 1 RPM in 15 s", function()
	local controller, drum = drum_pid(), new_drum()
	run(controller, drum, 45, 20)
	GAIN = 0.8
	local ok, err = pcall(run, controller, drum, 45, 30, function(t, rpm)
		if t >= 35 then T.near(rpm, 45, 1, "drum speed at t=%.2f s after the drag change at 20 s", t) end
	end, 20)
	GAIN = 1.0
	if not ok then error(err, 0) end
end)

-- A drive limited to 450 against a step to 400 RPM (which needs 400): the
-- output saturates for seconds. A naive PI integrates all that time and overshoots; this one
-- must stay within 1 %.
test("no windup: after saturating on a step to 400 RPM the overshoot stays under 1 %", function()
	local controller, drum = drum_pid({ out_max = 450, out_min = -450 }), new_drum()
	local saturated_s, peak = 0, 0
	run(controller, drum, 400, 30, function(_, rpm, u)
		if u >= 450 then saturated_s = saturated_s + DT end
		if rpm > peak then peak = rpm end
	end)
	T.at_least(saturated_s, 1, "seconds the drive spent saturated (the test needs saturation)")
	T.at_most(peak - 400, 4, "overshoot in RPM above the 400 RPM setpoint")

	-- The same step with an integral that ignores saturation, to show the
	-- scenario does wind up.
	local naive_i, naive_peak, naive = 0, 0, new_drum()
	local rpm = 0
	for _ = 1, 1000 do
		local err = 400 - rpm
		naive_i = naive_i + (2 / TAU) * err * DT
		local u = math.max(-450, math.min(450, 2 * err + naive_i))
		rpm = naive:step(u)
		if rpm > naive_peak then naive_peak = rpm end
	end
	T.at_least(naive_peak - 400, 20, "overshoot of the naive PI (shows the test exercises windup)")
end)

test("the integral term stays within i_min..i_max", function()
	local controller, drum = drum_pid({ i_min = -50, i_max = 50 }), new_drum()
	GAIN = 0.5 -- needs a drive of 90 for 45 RPM: more than kp alone can give
	local ok, err = pcall(run, controller, drum, 45, 30, function(t)
		T.check(controller.i_term <= 50 and controller.i_term >= -50,
			"integral term %.3f outside -50..50 at t=%.2f s", controller.i_term, t)
	end)
	GAIN = 1.0
	if not ok then error(err, 0) end
	T.near(controller.i_term, 50, 1e-9, "integral term pinned at i_max")
end)

test("no derivative kick: a setpoint step moves the output by kp times the step only", function()
	local controller, drum = drum_pid({ kd = 0.2 }), new_drum()
	local rpm = run(controller, drum, 45, 20)
	local before = controller.output
	local after = controller:update(100, rpm, DT)
	local expected = 2 * 55 + (2 / TAU) * 55 * DT -- the P and I terms of the new error
	T.near(after - before, expected, 0.5, "output change on a 45 -> 100 RPM setpoint step "
		.. "(a derivative of the error would add %.0f)", 0.2 * 55 / DT)
end)

test("the derivative acts on the measurement: a 10 RPM jump gives -kd*10/dt", function()
	local controller = pid.new({ kp = 0, ki = 0, kd = 0.3 })
	controller:update(50, 40, DT)
	T.equal(controller.d_term, 0, "derivative term on the first update (no previous sample)")
	controller:update(50, 50, DT)
	T.near(controller.d_term, -0.3 * 10 / DT, 1e-9, "derivative term after the measurement rose 10 RPM")
end)

test("output is clamped to out_min..out_max", function()
	local controller = pid.new({ kp = 10, out_min = -100, out_max = 100 })
	T.equal(controller:update(1000, 0, DT), 100, "output for a large positive error")
	T.equal(controller:update(-1000, 0, DT), -100, "output for a large negative error")
end)

test("dt == 0 returns the previous output and changes nothing; reset forgets", function()
	local controller = drum_pid()
	local u = controller:update(45, 0, DT)
	local i = controller.i_term
	T.equal(controller:update(400, 10, 0), u, "output with dt = 0")
	T.equal(controller.i_term, i, "integral after dt = 0")
	controller:reset()
	T.equal(controller.i_term, 0, "integral after reset")
	T.equal(controller.output, 0, "output after reset")
end)

test("bad arguments raise errors naming the argument, blamed on the caller", function()
	T.fails(function() pid.new() end, "pid.new: expects a table", "pid.new()")
	T.fails(function() pid.new({}) end, "pid.new: kp is required", "pid.new{}")
	local message = T.fails(function() pid.new({ kp = "2" }) end, "pid.new: kp must be a number", "kp = '2'")
	T.check(message:find("test_pid.lua", 1, true), "error blames the caller, got %q", message)
	T.fails(function() pid.new({ kp = 1, ki = 0 / 0 }) end, "pid.new: ki must be a number", "ki = NaN")
	T.fails(function() pid.new({ kp = 1, out_min = 5, out_max = 5 }) end, "out_min must be less than out_max",
		"out_min == out_max")
	T.fails(function() pid.new({ kp = 1, i_min = 1, i_max = -1 }) end, "i_min must not be greater than i_max",
		"i_min > i_max")
	local controller = pid.new({ kp = 1 })
	T.fails(function() controller:update(nil, 1, DT) end, "pid:update: setpoint must be a number", "setpoint nil")
	T.fails(function() controller:update(1, 0 / 0, DT) end, "pid:update: measurement must be a number",
		"measurement NaN")
	T.fails(function() controller:update(1, 1, -DT) end, "pid:update: dt must be a number >= 0", "dt < 0")
end)
