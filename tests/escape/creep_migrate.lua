-- memory creeping under pcall in migrate, a hot reload of the running driver the trigger
-- expect: memory cap exceeded
-- trigger: reload
local G = {}
local function creep()
	for i = 1, 1e7 do if not pcall(function() G[#G + 1] = { i } end) then break end end
end
return { name = "creep_migrate", version = "1", io = { lamp = "do0" },
	migrate = function(dev) dev.out.lamp = true creep() end, tick = function() end }
