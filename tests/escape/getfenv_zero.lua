-- getfenv(0): the real globals through a function environment
-- expect: attempt to call global 'getfenv'
local driver = { name = "getfenv_zero", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	getfenv(0)
end
return driver
