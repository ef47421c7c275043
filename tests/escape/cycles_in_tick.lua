-- vmac.cycles() inside a callback
-- expect: call it when the driver loads
local driver = { name = "cycles_in_tick", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	vmac.cycles()
end
return driver
