-- testing: the registry and assertions of the Lua tests (tests/lua/run.c),
-- which run in the driver sandbox: only what drivers get (no debug, io).
-- A test file calls test(name, fn) for each case; the assertions count
-- themselves, so a test that asserted nothing fails. Failure messages are
-- formatted only when an assertion fails, so checks in long simulation
-- loops stay cheap.

local testing = { pending = {}, count = 0 }

local format = string.format

-- Register a test case.
function testing.test(name, fn)
	testing.pending[#testing.pending + 1] = { name = name, fn = fn }
end

-- The cases registered since the last take (one test file's).
function testing.take()
	local cases = testing.pending
	testing.pending = {}
	return cases
end

local function describe(what, ...)
	if what == nil then return "check" end
	if select("#", ...) > 0 then return format(what, ...) end
	return what
end

local function show(v)
	if type(v) == "string" then return format("%q", v) end
	if type(v) == "number" then return format("%.6g", v) end
	return tostring(v)
end

-- An assertion failure: an error at the test's own line (level 3: the
-- caller of the assertion), so the message starts with its file and line.
local function fail(message)
	error(message, 3)
end

-- check(cond, what, ...): cond must be true.
function testing.check(cond, what, ...)
	testing.count = testing.count + 1
	if not cond then fail(describe(what, ...)) end
end

-- equal(actual, expected, what, ...)
function testing.equal(actual, expected, what, ...)
	testing.count = testing.count + 1
	if actual ~= expected then
		fail(describe(what, ...) .. ": expected " .. show(expected) .. ", got " .. show(actual))
	end
end

-- near(actual, expected, tolerance, what, ...): |actual - expected| <= tolerance
function testing.near(actual, expected, tolerance, what, ...)
	testing.count = testing.count + 1
	if type(actual) ~= "number" or actual ~= actual or math.abs(actual - expected) > tolerance then
		fail(describe(what, ...) .. ": expected " .. show(expected) .. " +- " .. show(tolerance)
			.. ", got " .. show(actual))
	end
end

-- at_most(actual, limit, what, ...): actual <= limit
function testing.at_most(actual, limit, what, ...)
	testing.count = testing.count + 1
	if type(actual) ~= "number" or actual ~= actual or actual > limit then
		fail(describe(what, ...) .. ": expected at most " .. show(limit) .. ", got " .. show(actual))
	end
end

-- at_least(actual, limit, what, ...): actual >= limit
function testing.at_least(actual, limit, what, ...)
	testing.count = testing.count + 1
	if type(actual) ~= "number" or actual ~= actual or actual < limit then
		fail(describe(what, ...) .. ": expected at least " .. show(limit) .. ", got " .. show(actual))
	end
end

-- fails(fn, text, what, ...): fn() raises an error whose message contains
-- text (plain, not a pattern). Returns the message.
function testing.fails(fn, text, what, ...)
	testing.count = testing.count + 1
	local ok, message = pcall(fn)
	if ok then
		fail(describe(what, ...) .. ": expected an error containing " .. show(text) .. ", but it succeeded")
	end
	message = tostring(message)
	if not message:find(text, 1, true) then
		fail(describe(what, ...) .. ": expected an error containing " .. show(text) .. ", got " .. show(message))
	end
	return message
end

return testing
