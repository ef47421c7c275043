-- Dishwasher driver (walking skeleton): idle and safe, fill valve, wash
-- motor and drain pump off. The cycle comes with the driver API.
-- Board I/O: docs/BOARD.md, "dishwasher".

local driver = {}

function driver.tick(inputs)
	return { digital = {} }
end

return driver
