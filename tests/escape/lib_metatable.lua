-- change the metatable of a library table
-- expect: cannot change a protected metatable
local driver = { name = "lib_metatable", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	setmetatable(table, {})
end
return driver
