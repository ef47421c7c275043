-- run: the Lua half of the stdlib's test runner (tests/lua/run.c). It is
-- the chunk of a fresh driver state, in the sandbox's own global table (no
-- print, io, debug or load: only what drivers get), called with the test
-- file's module name and a case's index:
--   0: require the test file (it registers its cases with testing.test) and
--      return the names of its cases, one a line;
--   n: require it again in this new state and run case n; return how many
--      assertions it made. A failing assertion or any error is an error of
--      the call, which run.c reports with its traceback.
local suite, index = ...
local T = require "testing"

require(suite)
local cases = T.take()
if index == 0 then
	local names = {}
	for i, case in ipairs(cases) do names[i] = case.name end
	return table.concat(names, "\n")
end
local before = T.count
cases[index].fn()
return T.count - before
