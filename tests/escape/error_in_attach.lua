-- an error in attach()
-- expect: attach boom
local driver = { name = "error_in_attach", version = "1", io = { lamp = "do0" } }
function driver.attach(dev)
	error('attach boom')
end
function driver.tick(dev) dev.out.lamp = true end
return driver
