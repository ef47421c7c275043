-- error() with a coroutine (drivers can make no userdata: this is the other non-table object)
-- expect: error object is not a string
local driver = { name = "error_thread", version = "1", io = { lamp = "do0" } }
function driver.tick(dev)
	error(coroutine.create(function() while true do end end))
end
return driver
