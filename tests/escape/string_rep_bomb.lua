-- string.rep of 1 GB in one C call
-- expect: string.rep result too large
local driver = { name = "string_rep_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.rep('x', 1e9)
end
return driver
