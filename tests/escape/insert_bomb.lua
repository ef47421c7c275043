-- table.insert at position -2^31 + 1: LuaJIT moves elements one by one from #t down to it (19 s in one C call)
-- expect: table\.insert: too costly
local driver = { name = "insert_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	table.insert({}, -2 ^ 31 + 1, true)
end
return driver
