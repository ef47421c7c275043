-- Washer driver (walking skeleton): keeps the machine idle and safe, every
-- valve, pump, lock and the drum motor off. The wash cycle comes with the
-- driver API and standard library (scripts/cycles/).
-- Board I/O: docs/BOARD.md, "washer".

local driver = {}

function driver.tick(inputs)
	return { digital = {}, pwm = 0 }
end

return driver
