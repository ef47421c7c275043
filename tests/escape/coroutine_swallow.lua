-- coroutine.resume catching the budget error
-- expect: time budget exceeded
local driver = { name = "coroutine_swallow", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	while true do coroutine.resume(coroutine.create(function() while true do end end)) end
end
return driver
