-- load: a bytecode chunk
-- expect: attempt to call global 'load'
local driver = { name = "load_bytecode", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	load('\27LJ\2')()
end
return driver
