-- run: the Lua test runner for stdlib/. From the repository root:
--   luajit tests/lua/run.lua [test_name.lua ...]
-- Runs every tests/lua/test_*.lua (or the ones named), one line per test,
-- then "N passed, N failed"; exits 1 if any failed. The JIT is off and the
-- stdlib modules load in a copy of the driver sandbox (tests/lua/sandbox.lua),
-- as in a driver.

package.path = "stdlib/?.lua;tests/lua/?.lua"
if jit then jit.off() end

local sandbox = require "sandbox"
local testing = require "testing"

local stdlib = sandbox.new_state("stdlib/")

-- Test files get the real globals, but require gives them stdlib modules
-- from the sandbox and the test helpers from tests/lua.
local function test_require(name)
	local path = "stdlib/" .. tostring(name) .. ".lua"
	local file = io.open(path, "rb")
	if file then
		file:close()
		return stdlib.require(name)
	end
	return require(name)
end

local function list_tests(args)
	if #args > 0 then
		local files = {}
		for i, name in ipairs(args) do
			files[i] = name:find("/", 1, true) and name or "tests/lua/" .. name
		end
		return files
	end
	local files = {}
	local ls = assert(io.popen("ls tests/lua/test_*.lua 2>/dev/null"))
	for line in ls:lines() do files[#files + 1] = line end
	ls:close()
	return files
end

local passed, failed = 0, 0

local function report_failure(label, message)
	failed = failed + 1
	print("FAIL " .. label)
	for line in tostring(message):gmatch("[^\n]+") do print("     " .. line) end
end

local files = list_tests(arg)
if #files == 0 then
	print("no tests found: run from the repository root")
	os.exit(1)
end

for _, path in ipairs(files) do
	local suite = path:match("([^/]+)%.lua$"):gsub("^test_", "")
	local chunk, err = loadfile(path)
	if not chunk then
		report_failure(suite .. ": (load)", err)
	else
		setfenv(chunk, setmetatable({ require = test_require }, { __index = _G }))
		local ok, load_err = xpcall(chunk, debug.traceback)
		local cases = testing.take()
		if not ok then
			report_failure(suite .. ": (load)", load_err)
		elseif #cases == 0 then
			report_failure(suite .. ": (load)", path .. " registered no tests")
		end
		for _, case in ipairs(cases) do
			local label = suite .. ": " .. case.name
			local before = testing.count
			local case_ok, message = xpcall(case.fn, function(m)
				if type(m) == "table" and m.assertion then return m.assertion end
				return debug.traceback(tostring(m), 1)
			end)
			if not case_ok then
				report_failure(label, message)
			elseif testing.count == before then
				report_failure(label, "the test asserted nothing")
			else
				passed = passed + 1
				print("ok   " .. label)
			end
		end
	end
end

print(passed .. " passed, " .. failed .. " failed")
os.exit(failed == 0 and 0 or 1)
