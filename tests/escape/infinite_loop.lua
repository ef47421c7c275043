-- while true do end
-- expect: time budget exceeded
local driver = { name = "infinite_loop", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	while true do end
end
return driver
