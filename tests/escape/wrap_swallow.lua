-- coroutine.wrap inside pcall catching the budget error
-- expect: time budget exceeded
local driver = { name = "wrap_swallow", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	while true do pcall(coroutine.wrap(function() while true do end end)) end
end
return driver
