-- rawset around the read-only library table
-- expect: rawset: this table is read-only
local driver = { name = "rawset_lib", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	rawset(math, 'floor', print)
end
return driver
