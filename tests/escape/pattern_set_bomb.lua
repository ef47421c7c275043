-- a bracket set of 60,000 characters tried at every place of a 256 KiB string (20 s in one C call here)
-- expect: string\.find: pattern too costly
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("a", 65536)
s = (s .. s) .. (s .. s)
local set = "[" .. string.rep("b", 60000) .. "]"
local driver = { name = "pattern_set_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.find(s, set)
end
return driver
