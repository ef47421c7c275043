-- memory creeping under pcall in attach
-- expect: memory cap exceeded
local G = {}
local function creep()
	for i = 1, 1e7 do if not pcall(function() G[#G + 1] = { i } end) then break end end
end
return { name = "creep_attach", version = "1", io = { lamp = "do0" },
	attach = function(dev) dev.out.lamp = true creep() end, tick = function(dev) dev.out.lamp = true end }
