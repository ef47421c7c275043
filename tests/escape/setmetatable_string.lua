-- setmetatable on a string
-- expect: bad argument #1 to 'setmetatable'
local driver = { name = "setmetatable_string", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	setmetatable('', {})
end
return driver
