-- require inside a callback (file I/O on the bus thread)
-- expect: only be required when the driver loads
local driver = { name = "require_in_tick", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	require 'pid'
end
return driver
