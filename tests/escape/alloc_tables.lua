-- millions of tables
-- expect: memory
local t = {}
for i = 1, 1e7 do t[i] = { i } end
return { name = "alloc_tables", version = "1", io = { lamp = "do0" }, tick = function(dev) dev.out.lamp = true end }
