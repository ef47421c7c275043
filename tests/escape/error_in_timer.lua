-- an error when a stdlib timer fires
-- expect: timer boom
local t = require("timer").new(0)
local driver = { name = "error_in_timer", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	if t:after(0, inputs.time) then error('timer boom') end
end
return driver
