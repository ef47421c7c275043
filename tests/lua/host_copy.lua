-- host_copy: for the Lua tests, the copy of dev.state that the host hands a
-- new version's migrate(dev, old_state) on a hot reload (core/driver/takeover.c,
-- copy_table): plain data only. Functions, coroutines and userdata are
-- dropped (a key or value of those types takes its entry with it),
-- metatables are not copied, and a table reached twice (shared, or a cycle)
-- is one table in the copy. Past 10,000 entries or 32 tables deep the host
-- refuses the reload; here that raises.

local host_copy = {}

local MAX_ENTRIES, MAX_DEPTH = 10000, 32

local PLAIN = { boolean = true, number = true, string = true }

local function copy(value, seen, count, depth)
	local kind = type(value)
	if PLAIN[kind] then return value, true end
	if kind ~= "table" then return nil, false end
	if seen[value] then return seen[value], true end
	if depth > MAX_DEPTH then error("host_copy: nested deeper than " .. MAX_DEPTH .. " tables", 0) end
	local t = {}
	seen[value] = t
	for k, v in next, value do -- raw, as lua_next: no __pairs
		count.entries = count.entries + 1
		if count.entries > MAX_ENTRIES then error("host_copy: more than " .. MAX_ENTRIES .. " entries", 0) end
		local key, key_ok = copy(k, seen, count, depth + 1)
		if key_ok then
			local val, val_ok = copy(v, seen, count, depth + 1)
			if val_ok then t[key] = val end
		end
	end
	return t, true
end

-- The copy of state (a table) as the new version's migrate gets it.
function host_copy.state(state)
	return (copy(state, {}, { entries = 0 }, 0))
end

return host_copy
