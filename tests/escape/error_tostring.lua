-- error() with a table whose __tostring never returns
-- expect: error object is not a string
local driver = { name = "error_tostring", version = "1", io = { lamp = "do0" } }
function driver.tick(dev)
	error(setmetatable({}, { __tostring = function() while true do end end,
		__index = function() while true do end end, __concat = function() while true do end end }))
end
return driver
