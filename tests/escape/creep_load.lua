-- memory creeping under pcall at the top of the file
-- expect: memory cap exceeded
local G = {}
for i = 1, 1e7 do if not pcall(function() G[#G + 1] = { i } end) then break end end
return { name = "creep_load", version = "1", io = { lamp = "do0" }, tick = function(dev) dev.out.lamp = #G > 0 end }
