-- string.format with a huge width
-- expect: invalid option|invalid format
local driver = { name = "format_width", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.format('%0999999d', 1)
end
return driver
