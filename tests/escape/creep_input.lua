-- memory creeping under pcall in input, an operator's command the trigger
-- expect: memory cap exceeded
-- trigger: input go
local G = {}
local function creep()
	for i = 1, 1e7 do if not pcall(function() G[#G + 1] = { i } end) then break end end
end
return { name = "creep_input", version = "1", io = { lamp = "do0" }, commands = { go = {} },
	input = function(dev) dev.out.lamp = true creep() return true end, tick = function() end }
