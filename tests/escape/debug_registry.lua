-- debug.getregistry: the host's registry
-- expect: attempt to index global 'debug'
local driver = { name = "debug_registry", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	debug.getregistry()
end
return driver
