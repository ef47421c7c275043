-- a 1 GiB string by doubling
-- expect: memory
local s = 'x'
for _ = 1, 30 do s = s .. s end
return { name = "alloc_1gib", version = "1", io = { lamp = "do0" }, tick = function(dev) dev.out.lamp = true end }
