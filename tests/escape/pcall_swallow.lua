-- a pcall loop that swallows the budget error
-- expect: time budget exceeded
local driver = { name = "pcall_swallow", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	while true do pcall(function() while true do end end) end
end
return driver
