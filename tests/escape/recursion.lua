-- unbounded recursion
-- expect: stack overflow|time budget exceeded
local driver = { name = "recursion", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	local function f() return 1 + f() end
	f()
end
return driver
