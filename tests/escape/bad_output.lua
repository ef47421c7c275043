-- an output that is not a boolean
-- expect: dev.out.lamp must be true, false or nil
local driver = { name = "bad_output", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	dev.out.lamp = 'on'
end
return driver
