-- memory creeping under pcall in detach, the host stopping the trigger
-- expect: host stops cleanly
-- trigger: stop
local G = {}
return { name = "creep_detach", version = "1", io = { lamp = "do0" }, tick = function() end,
	detach = function()
		for i = 1, 1e7 do if not pcall(function() G[#G + 1] = { i } end) then break end end
	end }
