-- setfenv: give a function other globals
-- expect: attempt to call global 'setfenv'
local driver = { name = "setfenv_escape", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	setfenv(1, {})
end
return driver
