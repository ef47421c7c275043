-- replace a library function
-- expect: library tables are read-only
local driver = { name = "lib_tamper", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.format = function() end
end
return driver
