-- loadstring: compile text at run time
-- expect: attempt to call global 'loadstring'
local driver = { name = "loadstring_code", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	loadstring('return 1')()
end
return driver
