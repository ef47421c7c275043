-- newproxy: userdata with a __gc finaliser
-- expect: attempt to call global 'newproxy'
local driver = { name = "newproxy_gc", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	newproxy(true)
end
return driver
