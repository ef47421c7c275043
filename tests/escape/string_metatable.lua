-- getmetatable(''): the string library behind the metatable
-- expect: string metatable is locked
local driver = { name = "string_metatable", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	local mt = getmetatable('')
	assert(type(mt) == 'table', 'string metatable is ' .. tostring(mt))
end
return driver
