-- an error inside a table.sort comparator
-- expect: comparator boom
local driver = { name = "error_in_sort", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	table.sort({ 3, 2, 1 }, function() error('comparator boom') end)
end
return driver
