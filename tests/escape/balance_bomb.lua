-- %b() scans to the end of a 1 MiB string of '(' from each of its places (some 5 minutes in one C call)
-- expect: string\.find: pattern too costly
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("(", 65536)
for _ = 1, 4 do
	s = s .. s
end
local driver = { name = "balance_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.find(s, "%b()")
end
return driver
