-- fake_host: for the Lua tests, the host's side of one machine that runs a
-- shipped driver (require "driver_NAME", tests/lua/run.c) on a simulated
-- board in virtual time: dev as docs/DRIVERS.md describes it (params at
-- their defaults, out, vars, state, set_level, event, checkpoint), the
-- manifest's io mapped from the board's reply ({digital, analog, encoder,
-- time}, as washer_plant senses) and to its outputs ({digital, pwm}, one
-- period later, as washer_plant actuates), and checkpoints: a plain copy of
-- dev.state (host_copy) saved at the end of a call that asked for one, and
-- every checkpoint_s of bus time (docs/DRIVERS.md, "Recovery").

local host_copy = require "host_copy"

local fake_host = {}

-- "di3" -> "di", 4 (the 1-based index of the board's lists)
local function channel(spec)
	local name = type(spec) == "table" and spec[1] or spec
	local kind, n = name:match("^(%a+)(%d*)$")
	return kind, tonumber(n) and tonumber(n) + 1, type(spec) == "table" and spec.scale or 1,
		type(spec) == "table" and spec.offset or 0
end

-- fake_host.new(driver, plant, {params = , checkpoint_s = , period_s = })
-- -> host. The driver is attached (driver.attach) but not ticked.
function fake_host.new(driver, plant, spec)
	spec = spec or {}
	local dev = { name = driver.name .. "-1", driver = driver.name, version = driver.version,
		out = {}, vars = {}, params = {}, state = {}, level = driver.level or 5,
		boards = { { name = driver.name .. "-1", minor = 0 } } }
	for name, p in pairs(driver.params or {}) do dev.params[name] = p.default end
	for name, value in pairs(spec.params or {}) do dev.params[name] = value end

	local host = { driver = driver, dev = dev, plant = plant, period_s = spec.period_s or 0.03,
		checkpoint_s = spec.checkpoint_s or 5, events = {}, levels = {}, asked = 0,
		saved = nil, saved_time = nil, pending = nil }
	local asked = false
	function dev.set_level(_, n) host.levels[#host.levels + 1] = n; dev.level = n; return true end
	function dev.event(_, text) host.events[#host.events + 1] = text end
	function dev.checkpoint() asked = true; host.asked = host.asked + 1 end

	-- The manifest's io, resolved once: inputs and outputs by kind.
	local ins, outs = {}, {}
	for name, spec_ in pairs(driver.io) do
		local kind, index, scale, offset = channel(spec_)
		local item = { name = name, kind = kind, index = index, scale = scale, offset = offset }
		if kind == "do" or kind == "pwm" then outs[#outs + 1] = item else ins[#ins + 1] = item end
	end
	local inputs = {} -- the same table every tick, as the host's

	-- The checkpoint, and what the driver published then (for the tests).
	local function save(now)
		host.saved, host.saved_time = host_copy.state(dev.state), now
		host.saved_vars = host_copy.state(dev.vars)
	end

	-- After a call into the driver at bus time now: a checkpoint if it asked,
	-- or if checkpoint_s passed since the last.
	local function after(now)
		if asked or (host.checkpoint_s > 0 and (host.saved_time == nil or now - host.saved_time >= host.checkpoint_s)) then
			save(now)
		end
		asked = false
	end

	-- One service of the machine: the board takes last period's outputs, the
	-- driver ticks on its reply, and the plant runs one period.
	function host.tick()
		plant.actuate(host.pending)
		local board = plant.sense()
		for _, i in ipairs(ins) do
			if i.kind == "di" then
				inputs[i.name] = board.digital[i.index] == true
			elseif i.kind == "ai" then
				inputs[i.name] = board.analog[i.index] * i.scale + i.offset
			else
				inputs[i.name] = board.encoder
			end
		end
		inputs.time = board.time
		driver.tick(dev, inputs)
		after(board.time)
		local digital = {}
		local pending = { digital = digital, pwm = 0 }
		for _, o in ipairs(outs) do
			if o.kind == "do" then
				digital[o.index] = dev.out[o.name] == true
			else
				local pwm = dev.out[o.name] or 0
				pending.pwm = pwm >= 0 and math.floor(pwm) or -math.floor(-pwm)
			end
		end
		host.pending = pending
		plant.step(host.period_s)
	end

	-- host.run(seconds, each): that many seconds of ticks; each(t) after
	-- every tick may return true to stop. Returns true when it stopped so.
	function host.run(seconds, each)
		for _ = 1, math.floor(seconds / host.period_s + 0.5) do
			host.tick()
			if each and each(plant.t) then return true end
		end
		return false
	end

	-- The event texts, one a line (for failure messages).
	function host.event_text()
		return table.concat(host.events, " | ")
	end

	-- The first event containing text (plain), or nil.
	function host.event(text)
		for _, e in ipairs(host.events) do
			if e:find(text, 1, true) then return e end
		end
		return nil
	end

	if driver.attach then driver.attach(dev) end
	return host
end

-- The host restarts: the boards went safe (every output off) for outage_s
-- of plant time, then the bus clock starts again at 0. Returns the plant.
function fake_host.outage(plant, outage_s, period_s)
	plant.actuate(nil)
	period_s = period_s or 0.03
	for _ = 1, math.floor(outage_s / period_s + 0.5) do plant.step(period_s) end
	plant.t = 0
	return plant
end

-- A new host for driver (a new instance) on the same plant, attached, and
-- recover(dev, saved) called with the old host's last checkpoint, age_s old.
function fake_host.recover(old_host, driver, age_s, spec)
	local host = fake_host.new(driver, old_host.plant, spec)
	assert(old_host.saved, "fake_host.recover: the old host saved no checkpoint")
	driver.recover(host.dev, { state = host_copy.state(old_host.saved), age_s = age_s,
		version = old_host.driver.version, time = 1700000000, restarted = true })
	return host
end

return fake_host
