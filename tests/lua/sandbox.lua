-- sandbox: loads stdlib modules (and example drivers) for the Lua tests the
-- way the driver sandbox will (docs/DRIVERS.md "The sandbox"): only the
-- allowed globals plus coroutine and a require that reads stdlib/ only.
-- Reading or setting any other global is an error, so a module that leans
-- on io, os or a global of its own fails its tests.

local sandbox = {}

local BASE = { "assert", "error", "ipairs", "pairs", "next", "select", "tonumber", "tostring", "type",
	"unpack", "pcall", "xpcall", "rawequal", "rawget", "rawset", "setmetatable", "getmetatable" }
local LIBS = { string = true, table = true, math = true, bit = true, coroutine = true }

local function copy(lib, except)
	local t = {}
	for k, v in pairs(lib) do
		if k ~= except then t[k] = v end
	end
	return t
end

local function strict(env)
	return setmetatable(env, {
		__index = function(_, name)
			error("global '" .. tostring(name) .. "' is not in the driver sandbox", 2)
		end,
		__newindex = function(_, name)
			error("assignment to global '" .. tostring(name) .. "': stdlib and drivers set no globals", 2)
		end,
	})
end

-- A fresh state: its own module cache, as each device has its own Lua state.
-- Returns { require = function(name), load = function(text, chunkname) }.
function sandbox.new_state(root)
	root = root or "stdlib/"
	local loaded, loading = {}, {}
	local state = {}

	local function env()
		local e = {}
		for _, name in ipairs(BASE) do e[name] = _G[name] end
		for name in pairs(LIBS) do e[name] = copy(_G[name], name == "string" and "dump" or nil) end
		e.require = state.require
		e._G = e
		return strict(e)
	end

	function state.load(text, chunkname)
		if text:byte(1) == 27 then error(chunkname .. ": bytecode is not loaded") end
		local chunk, err = loadstring(text, "@" .. chunkname)
		if not chunk then error(err, 0) end
		return setfenv(chunk, env())
	end

	function state.require(name)
		if type(name) ~= "string" or not name:match("^[%w_]+$") then
			error("require: module name must be letters, digits or _ (got " .. tostring(name) .. ")", 2)
		end
		if loaded[name] ~= nil then return loaded[name] end
		if loading[name] then error("require: module '" .. name .. "' requires itself (loop)", 2) end
		local path = root .. name .. ".lua"
		local file = io.open(path, "rb")
		if not file then error("require: no module '" .. name .. "' in " .. root, 2) end
		local text = file:read("*a")
		file:close()
		loading[name] = true
		local result = state.load(text, path)(name)
		loading[name] = nil
		if type(result) ~= "table" then error("require: " .. path .. " did not return a table", 2) end
		loaded[name] = result
		return result
	end

	return state
end

return sandbox
