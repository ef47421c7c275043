-- string.dump: turn a function into bytecode
-- expect: attempt to call field 'dump'
local driver = { name = "string_dump", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.dump(function() end)
end
return driver
