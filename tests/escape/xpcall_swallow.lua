-- an xpcall loop that swallows the budget error
-- expect: time budget exceeded
local driver = { name = "xpcall_swallow", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	while true do xpcall(function() while true do end end, function() end) end
end
return driver
