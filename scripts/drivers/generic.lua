-- Generic driver: for a board with raw I/O and no machine behind it yet.
-- Holds every output off; a starting point for a driver of your own
-- (copy it to your --drivers folder under a new name).
-- Board I/O: docs/BOARD.md, "generic".

local driver = {}

function driver.tick(inputs)
	return { digital = {}, pwm = 0 }
end

return driver
