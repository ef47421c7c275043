-- %f with a 60,000-character set, tested twice at each place of a 256 KiB string (33 s in one C call)
-- expect: string\.find: pattern too costly
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("a", 65536)
s = (s .. s) .. (s .. s)
local frontier = "%f[" .. string.rep("b", 60000) .. "]"
local driver = { name = "frontier_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.find(s, frontier)
end
return driver
