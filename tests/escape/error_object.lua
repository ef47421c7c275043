-- error() with a table, not a string
-- expect: error object is not a string
local driver = { name = "error_object", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	error({ code = 1 })
end
return driver
