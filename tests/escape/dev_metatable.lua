-- a metatable on dev whose __index never returns, and dev.out removed: the host reads raw
-- expect: dev.out must stay a table
local loop = { __index = function() while true do end end, __newindex = function() while true do end end }
local driver = { name = "dev_metatable", version = "1", io = { lamp = "do0" } }
function driver.tick(dev)
	setmetatable(dev, loop)
	rawset(dev, "out", nil)
end
return driver
