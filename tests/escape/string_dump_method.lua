-- (''):dump(): string.dump through the string metatable
-- expect: attempt to call method 'dump'
local driver = { name = "string_dump_method", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	local s = ''
	s:dump()
end
return driver
