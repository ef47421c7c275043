-- vmac test: finds *_test.lua files, runs each test() in a fresh virtual
-- world (core/vtest/world.c: the real host bus, drivers and board firmware
-- on one virtual clock), and reports. The test API and the options are in
-- docs/TESTING.md; this file is that API's implementation.

local world = require "vmac.world"
local reports = dofile(VMAC_ROOT .. "/core/vtest/report.lua")

jit.off() -- count hooks (the runaway guard) do not fire inside JIT traces

-- ---- options ----

-- Parsed by vmac's option table (core/cli/vmac.c, test_cmd), which also
-- answers --help and refuses unknown options and bad values.
local opts = OPTS

local function usage_error(msg)
	io.stderr:write("vmac test: ", msg, "\n(vmac test --help for the options)\n")
	os.exit(2)
end

if opts.drivers then
	local f = io.open(opts.drivers .. "/.", "r")
	if not f then usage_error("--drivers " .. opts.drivers .. ": no such folder") end
	f:close()
end

-- --replay FILE: no tests, one replay (docs/RECORDING.md). Exit 0 as
-- recorded (or the recorded failure gone), 1 differs or fails, 2 cannot run.
if opts.replay then
	local f, err = io.open(opts.replay, "rb")
	if not f then usage_error("--replay: " .. err) end
	local text = f:read("*a")
	f:close()
	local settings = opts.drivers and { { "drivers", opts.drivers } } or {}
	local rc, report = world.replay(text, settings, opts.drivers == nil)
	io.stdout:write(report)
	os.exit(rc == 0 and 0 or rc == 1 and 1 or 2)
end

-- Opened now, so a folder that does not exist is said before the tests run.
local junit_file
if opts.junit then
	local err
	junit_file, err = io.open(opts.junit, "w")
	if not junit_file then usage_error("--junit: " .. err) end
end

-- ---- finding test files ----

local files
do
	local roots = #opts.paths > 0 and opts.paths or { VMAC_ROOT .. "/tests", VMAC_ROOT .. "/scripts" }
	local missing
	files, missing = dofile(VMAC_ROOT .. "/core/vtest/find.lua")(roots, os.getenv("PWD"))
	if missing then usage_error(missing .. ": no such file or folder") end
	if #files == 0 then
		io.stderr:write("vmac test: no *_test.lua files under ", table.concat(roots, ", "), "\n")
		os.exit(1)
	end
end

-- ---- failures ----

local Failure = {}
Failure.__index = Failure
Failure.__tostring = function(f) return f.message end

local current -- the running test: { file, world, boards, always, ... }
local loading -- the test file whose top level runs, before its tests do

-- file:line of the innermost frame that is in the test file.
local function where(level)
	level = (level or 2) + 1
	while true do
		local info = debug.getinfo(level, "Sl")
		if not info then return nil end
		local file = current and current.file or loading
		if file and info.source == "@" .. file and info.currentline > 0 then
			return file .. ":" .. info.currentline
		end
		level = level + 1
	end
end

-- Every check a test makes is counted: a test that made none fails.
local function checked() current.checks = current.checks + 1 end

local function fail(message, extra)
	local f = setmetatable({ message = message, where = where(2) }, Failure)
	if extra then for k, v in pairs(extra) do f[k] = v end end
	error(f, 0)
end

-- A call into the world the test asked for (plugging a board, an action,
-- wire faults): what it refuses (an unknown plant, a bad argument) is the
-- test's mistake, so it fails the test at the test's line, not here.
-- `what` goes ahead of the world's message ("board{...}: ").
local function world_call(what, fn, ...)
	local ok, a, b = pcall(fn, ...)
	if not ok then fail(what .. (tostring(a):gsub("^[^:]*:%d+: ", ""))) end
	return a, b
end

local function show(v)
	if type(v) == "string" then return string.format("%q", v) end
	if type(v) == "number" then return string.format("%.6g", v) end
	return tostring(v)
end

-- ---- the scene ----

local Board = {}

local methods -- the world's methods, for the accessors that checks call

local function W()
	if not current.world then
		current.world = world_call("", world.new, current.settings, opts.seed)
		methods = methods or getmetatable(current.world).__index
		current.world:trace(current.trace_file, current.trace_name)
		for _, c in ipairs(current.costs) do current.world:driver_cost(c[1], c[2]) end
	end
	return current.world
end

local function io_view(b)
	local w, io, board_name = current.world, methods.io, b.name
	return setmetatable({}, {
		__index = function(_, name)
			local v, why = io(w, board_name, name)
			if v == nil then
				if why ~= "" then fail(b.name .. ": no I/O names: " .. why) end
				fail(string.format("%s has no I/O named '%s' (its driver names: %s)", b.name, name,
					table.concat(current.world:io_names(b.name), ", ")))
			end
			return v
		end,
		__newindex = function() fail("the board's I/O is read-only: act on the plant with b:set()") end,
	})
end

local function make_board(spec)
	if type(spec) ~= "table" then fail("board{...}: expected a table with name and plant") end
	local name, plant = spec.name, spec.plant
	if type(name) ~= "string" then fail("board{...}: name is required (a string)") end
	if type(plant) ~= "string" then
		fail("board{...}: plant is required (washer, dishwasher, lights, generic, or a plant of your own: "
			.. "plants/NAME.lua)")
	end
	if spec.params ~= nil and type(spec.params) ~= "table" then fail("board{...}: params must be a table") end
	if spec.clock ~= nil and type(spec.clock) ~= "table" then
		fail("board{...}: clock must be a table such as {ppm = 100, offset = 2.5, jitter = 20e-6}")
	end
	local w = W()
	-- the driver: as given, else the plant's (a Lua plant may name another)
	local _, driver = world_call("board{...}: ", w.board, w, name, plant, spec.driver, spec.major, spec.minor)
	if spec.clock then world_call("board{...}: clock: ", w.set_clock, w, name, spec.clock) end
	for k, v in pairs(spec.params or {}) do
		world_call("board{...}: ", w.config, w, "driver." .. driver .. ".param." .. k, tostring(v))
	end
	local b = { name = name, plant_kind = plant, driver = driver }
	b.io = io_view(b)
	b.inp, b.out = b.io, b.io
	local var_of, plant_of = methods.var, methods.plant -- read at every check: no lookups on the way
	b.var = setmetatable({}, { __index = function(_, k) return var_of(w, name, k) end })
	b.plant = setmetatable({}, { __index = function(_, k) return plant_of(w, name, k) end })
	current.boards[#current.boards + 1] = b
	return setmetatable(b, Board)
end

Board.__index = function(b, k)
	if k == "state" then return methods.state(current.world, b.name) end
	if k == "device" then return current.world:device(b.name) end
	if k == "clock" then return methods.clock(current.world, b.name) end
	return Board[k]
end
Board.__tostring = function(b) return "board " .. b.name end

local function check_action(verb, name, value)
	if type(name) ~= "string" then fail(string.format("b:%s(action, value): the action must be a name, not %s", verb,
		show(name))) end
	if value ~= nil and type(value) ~= "number" and type(value) ~= "boolean" then
		fail(string.format("b:%s(%q, value): the value must be a number or a boolean, not %s", verb, name,
			show(value)))
	end
end

-- What the test did, for the failure report (details): board is the
-- board's name, or nil for what acts on every board (the host).
local function acted(board_name, text)
	local list = current.actions
	list[#list + 1] = { time = current.world and current.world:now() or 0, board = board_name, text = text }
end

local function set_plant(b, verb, name, value)
	world_call("", current.world.set, current.world, b.name, name, value)
	acted(b.name, verb)
end

function Board:set(name, value)
	check_action("set", name, value)
	set_plant(self, string.format("set(%q, %s)", name, show(value == nil and 1 or value)), name,
		value == nil and 1 or value)
end

function Board:try_set(name, value)
	check_action("try_set", name, value)
	local ok = pcall(current.world.set, current.world, self.name, name, value == nil and 1 or value)
	if ok then acted(self.name, string.format("try_set(%q, %s)", name, show(value == nil and 1 or value))) end
	return ok
end

function Board:press(name)
	check_action("press", name)
	set_plant(self, string.format("press(%q)", name), name, 1)
end
function Board:release(name)
	check_action("release", name)
	set_plant(self, string.format("release(%q)", name), name, 0)
end
function Board:open_door() set_plant(self, "open_door()", "door", 0) end
function Board:close_door() set_plant(self, "close_door()", "door", 1) end

local function check_input(verb, name, value)
	if type(name) ~= "string" then
		fail(string.format("b:%s(name, value): name must be a command or variable's name, not %s", verb, show(name)))
	end
	local t = type(value)
	if value ~= nil and t ~= "boolean" and t ~= "number" and t ~= "string" then
		fail(string.format("b:%s(%q, value): the value must be nil, a boolean, a number or a string, not a %s", verb,
			name, t))
	end
end

function Board:try_input(name, value)
	check_input("try_input", name, value)
	local rc, reply = current.world:input(self.name, name, value)
	acted(self.name, string.format("try_input(%q%s): %s", name, value == nil and "" or ", " .. show(value),
		rc == 0 and "accepted" or "refused"))
	return rc == 0, reply
end

function Board:input(name, value)
	check_input("input", name, value)
	checked()
	local rc, reply = current.world:input(self.name, name, value)
	acted(self.name, string.format("input(%q%s): %s", name, value == nil and "" or ", " .. show(value),
		rc == 0 and "accepted" or "refused"))
	if rc ~= 0 then
		fail(string.format("%s: input %s(%s) %s: %s", self.name, name, value == nil and "" or show(value),
			rc > 0 and "refused" or "failed", reply))
	end
	return reply
end

function Board:unplug() current.world:connect(self.name, false, true) acted(self.name, "unplug()") end
function Board:replug() current.world:connect(self.name, true, true) acted(self.name, "replug()") end
function Board:power_off() current.world:connect(self.name, true, false) acted(self.name, "power_off()") end
function Board:power_on() current.world:connect(self.name, true, true) acted(self.name, "power_on()") end
function Board:faults(spec)
	if spec ~= nil and type(spec) ~= "table" then fail("b:faults{...}: expected a table such as {drop = 0.01}") end
	world_call("", current.world.faults, current.world, self.name, spec or {})
	local parts = {}
	for k, v in pairs(spec or {}) do parts[#parts + 1] = k .. " = " .. show(v) end
	table.sort(parts)
	acted(self.name, "faults{" .. table.concat(parts, ", ") .. "}")
end
function Board:history() return current.world:history(self.name) end
-- A step of the board's drift (a change of temperature), from now on.
function Board:clock_step(ppm)
	if type(ppm) ~= "number" then fail("b:clock_step(ppm): ppm must be a number, not " .. show(ppm)) end
	world_call("b:clock_step: ", current.world.clock_step, current.world, self.name, ppm)
	acted(self.name, string.format("clock_step(%s)", show(ppm)))
end

-- ---- running time ----

local function now() return current.world and current.world:now() or 0 end

-- The grace of an always: `within` seconds, or "N period(s)": N times the
-- longest service period the host gives the test's boards, read when the
-- condition turns false (a device's period can change with its level).
local function grace_s(inv)
	if not inv.periods then return inv.within end
	local longest_us = 0
	for _, b in ipairs(current.boards) do
		local d = current.world:device(b.name)
		if d and d.period_us > longest_us then longest_us = d.period_us end
	end
	if longest_us == 0 then
		fail(string.format("always: %s (declared at %s) has a grace of %s, but no board is served yet: "
			.. "no period to count", inv.what, inv.where, inv.within_text), { where = inv.where })
	end
	return inv.periods * longest_us / 1e6
end

local function violated(inv, t, note)
	fail(string.format("always: %s (declared at %s) was violated at %.6f s, tick %d%s", inv.what, inv.where, t,
		math.floor(t / current.world:slot() + 0.5), note or ""), { time = t })
end

-- An always with a grace whose condition is false: it fails once it has
-- been false for longer than the grace. `advance` stops the run just past
-- the earliest such moment (current.grace_due) to look again.
local function held_false(inv, t)
	if not inv.false_since then
		inv.false_since, inv.grace = t, grace_s(inv)
		local due = t + inv.grace
		if not current.grace_due or due < current.grace_due then
			current.grace_due, current.grace_new = due, true
		end
	elseif t - inv.false_since > inv.grace then
		violated(inv, t, string.format(": false since %.6f s, longer than its grace of %g s%s", inv.false_since,
			inv.grace, inv.periods and " (" .. inv.within_text .. ")" or ""))
	end
end

-- The earliest moment a pending grace runs out, or nil.
local function next_grace_due()
	local due
	for _, inv in ipairs(current.always) do
		if inv.false_since and (not due or inv.false_since + inv.grace < due) then
			due = inv.false_since + inv.grace
		end
	end
	return due
end

-- Runs at every check (world.c), so it stays lean: no pcall per condition;
-- an error raised inside one is named by run_test through current.checking.
local function check_invariants()
	local list = current.always
	for i = 1, #list do
		local inv = list[i]
		current.checking = inv
		local held = inv.fn()
		current.checking = nil
		if not held then
			if inv.within then
				held_false(inv, now())
			else
				violated(inv, now())
			end
		elseif inv.false_since then
			-- Nothing it reads changed between the last check and this one,
			-- so it was false all that time.
			local t = now()
			if t - inv.false_since > inv.grace then
				violated(inv, inv.false_since + inv.grace, string.format(": false from %.6f s to %.6f s, longer "
					.. "than its grace of %g s%s", inv.false_since, t, inv.grace,
					inv.periods and " (" .. inv.within_text .. ")" or ""))
			end
			inv.false_since = nil
			current.grace_due = next_grace_due()
		end
	end
end

-- ---- every: test-side behaviour on a clock ----

local Every = {}
Every.__index = Every

-- Stops it: fn is not called again (also from inside fn).
function Every:stop() self.stopped = true end

-- The earliest time an every that runs is due, or nil.
local function next_every_due()
	local due
	for _, e in ipairs(current.every) do
		if not e.stopped and (not due or e.next_t < due) then due = e.next_t end
	end
	return due
end

-- Calls each every due by time t (in the order they were declared).
-- current.in_every names the one running: an error it raises is named by
-- run_test, and it may not run the clock itself.
local function run_every(t)
	for _, e in ipairs(current.every) do
		if not e.stopped and e.next_t <= t then
			e.calls = e.calls + 1
			e.next_t = e.start + (e.calls + 1) * e.dt -- not a sum of dt: no drift over an hour
			current.in_every = e
			e.fn(t)
			current.in_every = nil
		end
	end
end

-- every(seconds, fn): fn(t) every `seconds` of virtual time from now,
-- while the test runs the clock; returns a handle with :stop().
local function every(seconds, fn)
	if type(seconds) ~= "number" or not (seconds > 0) or seconds == math.huge then
		fail("every(seconds, fn): seconds must be a number > 0, not " .. show(seconds))
	end
	if type(fn) ~= "function" then fail("every(seconds, fn): fn must be a function, not " .. show(fn)) end
	local start = now()
	local e = setmetatable({ dt = seconds, fn = fn, start = start, calls = 0, next_t = start + seconds,
		where = where(2) or "?" }, Every)
	current.every[#current.every + 1] = e
	return e
end

-- Advance to `until_t`, stopping early when cond() holds; true if it did.
-- An always whose grace is running stops the run just past the moment the
-- grace runs out, to look at its condition there (nothing else may move
-- then, so no check would run). An every stops it at its time, to call its
-- fn (which acts between runs of the clock, as the test does).
local function advance(until_t, cond)
	if current.in_every then
		fail(string.format("every (declared at %s): its fn cannot run the clock (run_for, run_until, eventually): "
			.. "it is called from inside one", current.in_every.where))
	end
	local w = W()
	local limited = false
	if until_t > opts.time_limit then until_t, limited = opts.time_limit, true end
	local check, met
	if cond or #current.always > 0 then
		check = function()
			check_invariants()
			met = cond ~= nil and cond() and true or false
			return met or current.grace_new
		end
	end
	while true do
		current.grace_new = false
		local stop_at = until_t
		local due = current.grace_due
		if due and due + 1e-9 < stop_at then stop_at = due + 1e-9 end
		local every_due = current.every[1] and next_every_due()
		if every_due and every_due < stop_at then stop_at = every_due end
		local stopped, plant_failed = w:run(stop_at, check)
		if plant_failed then fail(plant_failed) end
		if stopped and met then return true end
		if not stopped then
			if every_due and every_due <= stop_at then run_every(stop_at) end
			if stop_at >= until_t then break end
			if due and stop_at >= due then check_invariants() end -- the grace ran out: still false fails it
		end
	end
	if limited then
		fail(string.format("the test ran past the virtual-time limit of %g s (--time-limit)", opts.time_limit))
	end
	return false
end

local function run_for(seconds)
	if type(seconds) ~= "number" or not (seconds >= 0) then
		fail("run_for(seconds): seconds must be a number >= 0, not " .. show(seconds))
	end
	advance(now() + seconds)
end

local function wait_for(verb, cond, timeout, what)
	checked()
	if type(cond) ~= "function" then fail(verb .. "(condition, timeout): the condition must be a function") end
	if type(timeout) ~= "number" or not (timeout >= 0) then
		fail(verb .. "(condition, timeout): timeout must be seconds, not " .. show(timeout))
	end
	local start = now()
	W()
	if cond() then return 0 end
	if not advance(start + timeout, cond) then
		fail(string.format("%s: %s not reached within %g s (from %.3f s to %.3f s of virtual time)", verb,
			what or "the condition", timeout, start, now()))
	end
	return now() - start
end

local function run_until(cond, timeout, what) return wait_for("run_until", cond, timeout, what) end
local function eventually(cond, within, what) return wait_for("eventually", cond, within, what) end

-- always(what, cond [, {within = SECONDS or "N period(s)"}])
local function always(what, fn, options)
	if type(what) == "function" then what, fn = fn, what end
	if type(fn) ~= "function" then fail("always(description, condition): the condition must be a function") end
	if options ~= nil and type(options) ~= "table" then
		fail("always(description, condition, options): options must be a table such as {within = 0.05}")
	end
	checked()
	local inv = { what = what or "condition", fn = fn, where = where(2) or "?" }
	local within = options and options.within
	if type(within) == "number" and within >= 0 then
		inv.within = within
		inv.grace = within
	elseif type(within) == "string" and within:match("^%s*%d*%.?%d+%s+periods?%s*$") then
		inv.within, inv.within_text = true, within:match("^%s*(.-)%s*$")
		inv.periods = tonumber(within:match("%d*%.?%d+"))
	elseif within ~= nil then
		fail(string.format("always: within = %s: expected seconds (a number >= 0) or \"N periods\" "
			.. "(\"1 period\")", show(within)))
	end
	current.always[#current.always + 1] = inv
	if current.world then check_invariants() end
	return inv
end

-- ---- expectations ----

local function expect(cond, what)
	checked()
	if not cond then fail("expected " .. (what or "the condition to hold") .. string.format(" (at %.3f s)", now())) end
end

local function expect_eq(actual, expected, what)
	checked()
	if actual ~= expected then
		fail(string.format("%s: expected %s, got %s (at %.3f s)", what or "value", show(expected), show(actual), now()),
			{ expected = expected, actual = actual })
	end
end

local function expect_near(actual, expected, tolerance, what)
	checked()
	if type(expected) ~= "number" or type(tolerance) ~= "number" then
		fail(string.format("expect_near(actual, expected, tolerance): expected and tolerance must be numbers, not %s "
			.. "and %s", show(expected), show(tolerance)))
	end
	if type(actual) ~= "number" or math.abs(actual - expected) > tolerance then
		fail(string.format("%s: expected %s +/- %s, got %s (at %.3f s)", what or "value", show(expected),
			show(tolerance), show(actual), now()), { expected = expected, actual = actual })
	end
end

local function events(filter)
	local all = current.world and current.world:events(1) or {}
	if not filter then return all end
	local out = {}
	for _, e in ipairs(all) do
		if (not filter.kind or e.kind == filter.kind) and (not filter.device or e.device == filter.device)
			and (not filter.text or e.text:find(filter.text, 1, true)) then
			out[#out + 1] = e
		end
	end
	return out
end

local function expect_event(filter, what)
	checked()
	if type(filter) == "string" then filter = { kind = filter } end
	local got = events(filter)
	if #got == 0 then
		local parts = {}
		for k, v in pairs(filter) do parts[#parts + 1] = k .. "=" .. show(v) end
		table.sort(parts)
		fail(string.format("expected %s: no event with %s by %.3f s", what or "an event", table.concat(parts, ", "),
			now()))
	end
	return got[1]
end

local function config(settings)
	if current.world then fail("config{...} must come before the first board") end
	if type(settings) ~= "table" then fail("config{...}: expected a table of settings") end
	local keys = {}
	for k in pairs(settings) do keys[#keys + 1] = k end
	table.sort(keys)
	for _, k in ipairs(keys) do current.settings[#current.settings + 1] = { k, tostring(settings[k]) } end
end

-- driver_cost(name, seconds): every call of driver `name` takes that much
-- virtual time (a slow driver, modelled); a tick past its limit fails as on
-- the host.
local function driver_cost(name, seconds)
	if type(name) ~= "string" or type(seconds) ~= "number" then
		fail("driver_cost(name, seconds) expects a driver name and a number of seconds")
	end
	current.costs[#current.costs + 1] = { name, seconds }
	if current.world then world_call("", current.world.driver_cost, current.world, name, seconds) end
end

local function kitchen(spec)
	spec = spec or {}
	local params = spec.params or {}
	return {
		washer = make_board { name = "washer-1", plant = "washer", params = params.washer },
		dishwasher = make_board { name = "dishwasher-1", plant = "dishwasher", params = params.dishwasher },
		lights = make_board { name = "lights-1", plant = "lights", params = params.lights },
	}
end

local function stop_host()
	W():stop_host()
	acted(nil, "stop_host()")
end

-- A host crash (SIGKILL, a power cut): gone at once, no word to the boards.
local function crash_host()
	W():crash_host()
	acted(nil, "crash_host()")
end

-- A flight recording (its text) replayed against the driver under test
-- (--drivers DIR, else the shipped one): the test fails where an output
-- differs or the driver fails (docs/RECORDING.md, "Replay").
local function replay(text)
	if type(text) ~= "string" then fail("replay(text): expects the recording's text") end
	checked()
	local rc, report = world.replay(text, current.settings, false)
	if rc ~= 0 then fail(report) end
	return report
end

-- A new host after crash_host: it discovers the boards
-- again and offers each machine its last checkpoint (recover).
local function start_host()
	W():start_host()
	acted(nil, "start_host()")
end

-- Keep the frames of the test file from a traceback.
local test_frames = reports.test_frames

local results = {}

-- ---- loading test files ----

local tests = {}      -- { file, name, fn, line }
local file_errors = {} -- { file, message, where } as failed tests

local function load_file(file)
	local found = {}
	local env = setmetatable({}, { __index = _G })
	env.test = function(name, fn)
		if type(name) ~= "string" or type(fn) ~= "function" then
			error("test(name, function) expects a name and a function", 2)
		end
		local info = debug.getinfo(2, "l")
		found[#found + 1] = { file = file, name = name, fn = fn, line = info and info.currentline or 0 }
	end
	for k, v in pairs {
		board = make_board, kitchen = kitchen, config = config, driver_cost = driver_cost,
		run_for = run_for, run_until = run_until,
		eventually = eventually, always = always, every = every, expect = expect, expect_eq = expect_eq,
		expect_near = expect_near, expect_event = expect_event, events = events, now = now, fail = fail,
		stop_host = stop_host, crash_host = crash_host, start_host = start_host, replay = replay,
	} do
		env[k] = v
	end
	-- A file that does not load runs none of its tests: it is one failure,
	-- at the line of the error.
	local function cannot_load(message)
		file_errors[#file_errors + 1] = { file = file, name = "(loading the file)", message = message,
			where = message:match("^([^:]+:%d+):") or file }
	end
	local chunk, err = loadfile(file)
	if not chunk then return cannot_load(err) end
	setfenv(chunk, env)
	-- The top level of a file is held to --timeout as a test is.
	local deadline = world.wall() + opts.timeout
	debug.sethook(function()
		if world.wall() > deadline then
			debug.sethook()
			error(string.format("loading the file took more than %g s of wall time (--timeout): an endless loop "
				.. "at its top level?", opts.timeout), 2)
		end
	end, "", 100000)
	loading = file
	local ok, lerr = xpcall(chunk, function(e)
		if getmetatable(e) == Failure then e = (e.where and e.where .. ": " or "") .. e.message end
		local frames = test_frames(debug.traceback("", 2), file)
		return tostring(e) .. (#frames > 0 and "\n  from " .. table.concat(frames, "\n  from ") or "")
	end)
	debug.sethook()
	loading = nil
	if not ok then return cannot_load(lerr) end
	if #found == 0 then return cannot_load(file .. ": defines no test (call test(name, function() ... end))") end
	for _, t in ipairs(found) do tests[#tests + 1] = t end
end

for _, f in ipairs(files) do load_file(f) end

local selected = {}
for _, t in ipairs(tests) do
	if not opts.filter or (t.file .. ": " .. t.name):find(opts.filter, 1, true) then
		selected[#selected + 1] = t
	end
end

if opts.list then
	for _, t in ipairs(selected) do print(t.file .. ": " .. t.name) end
	for _, e in ipairs(file_errors) do print(e.file .. ": " .. e.name .. "  [cannot load]") end
	os.exit(#file_errors > 0 and 1 or 0)
end

-- ---- running ----

local trace_file
if opts.trace then
	local err
	trace_file, err = io.open(opts.trace, "w")
	if not trace_file then usage_error("--trace: " .. err) end
	trace_file:write("test,time_s,board,io,value\n")
end

local function run_test(t)
	current = { file = t.file, settings = {}, boards = {}, always = {}, every = {}, checks = 0, costs = {},
		actions = {}, trace_file = trace_file, trace_name = t.file .. ": " .. t.name }
	if opts.drivers then current.settings[1] = { "drivers", opts.drivers } end
	local wall0 = world.wall()
	local deadline = wall0 + opts.timeout
	debug.sethook(function()
		if world.wall() > deadline then
			debug.sethook()
			fail(string.format("the test took more than %g s of wall time (--timeout): an endless loop?",
				opts.timeout))
		end
	end, "", 100000)
	-- finished says the body ran to its end: an error that never reached
	-- the handler (lost on its way out) must not read as a pass.
	local finished = false
	local ok, err = xpcall(function() t.fn() finished = true end, function(e)
		if getmetatable(e) == Failure then return e end
		local msg = tostring(e)
		local inv = current.checking
		local ev = current.in_every
		if ev then
			local f = setmetatable({ message = string.format("every (declared at %s): its fn raised: %s", ev.where,
				msg), error = true, where = msg:match("^([^:]+:%d+):") or where(2) }, Failure)
			f.frames = test_frames(debug.traceback("", 2), t.file)
			return f
		end
		if inv then
			local f = setmetatable({ message = string.format("always (%s): the condition raised: %s", inv.what, msg),
				error = true, where = inv.where }, Failure)
			f.frames = test_frames(debug.traceback("", 2), t.file)
			return f
		end
		local f = setmetatable({ message = msg, error = true }, Failure)
		f.where = msg:match("^([^:]+:%d+):") or where(2)
		f.frames = test_frames(debug.traceback("", 2), t.file)
		return f
	end)
	debug.sethook()
	if ok and not finished then
		ok, err = false, setmetatable({ message = "the test's body did not run to its end, and no error said why "
			.. "(an error was lost on its way out)", where = t.file .. ":" .. t.line }, Failure)
	elseif ok and current.checks == 0 then
		ok, err = false, setmetatable({ message = "the test checked nothing: no expect, expect_eq, expect_near, "
			.. "expect_event, eventually, run_until, always or board:input ran", where = t.file .. ":" .. t.line },
			Failure)
	end
	local r = { file = t.file, name = t.name, wall = world.wall() - wall0, virtual = now(),
		frames = current.world and current.world:frames() or 0 }
	if not ok then
		r.failure = err
		r.details = reports.details(current, opts.history)
	end
	if current.world then current.world:free() end
	current = nil
	collectgarbage()
	return r
end

local total = #selected + #file_errors
if opts.tap then
	print("TAP version 13")
	print("1.." .. total)
end

local reporter = reports.reporter(opts.tap)
local report = reporter.report

for _, e in ipairs(file_errors) do
	report { file = e.file, name = e.name, failure = setmetatable({ message = e.message }, Failure), where = e.where,
		virtual = 0, wall = 0 }
	results[#results + 1] = { file = e.file, name = e.name, failure = { message = e.message }, virtual = 0, wall = 0 }
end

for _, t in ipairs(selected) do
	local r = run_test(t)
	results[#results + 1] = r
	report(r)
end

if trace_file then trace_file:close() end

if junit_file then reports.junit(junit_file, results, reporter.n, reporter.failed) end

local n, failed, virtual_sum, wall_sum = reporter.n, reporter.failed, reporter.virtual, reporter.wall
local summary = string.format("%d test%s, %d failed; %s of virtual time in %.2f s of wall time", n,
	n == 1 and "" or "s", failed, reports.human_duration(virtual_sum), wall_sum)
if wall_sum >= 0.01 and virtual_sum > 0 then summary = summary .. string.format(" (%.0fx real time)", virtual_sum / wall_sum) end
if opts.tap then
	print("# " .. summary)
else
	print(summary)
end
if n == 0 then
	io.stderr:write("vmac test: no tests found\n")
	return 1
end
return failed > 0 and 1 or 0
