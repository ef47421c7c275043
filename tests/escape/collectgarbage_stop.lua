-- collectgarbage('stop'): starve the host of memory
-- expect: attempt to call global 'collectgarbage'
local driver = { name = "collectgarbage_stop", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	collectgarbage('stop')
end
return driver
