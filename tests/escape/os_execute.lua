-- os.execute: run a program (os has only clock)
-- expect: attempt to call field 'execute'
local driver = { name = "os_execute", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	os.execute('true')
end
return driver
