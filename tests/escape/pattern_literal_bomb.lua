-- a 60,000-character literal pattern tried at every place of a 1 MiB string (some 4.5 minutes in one C call)
-- expect: string\.find: pattern too costly
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("a", 65536)
for _ = 1, 4 do
	s = s .. s
end
local literal = string.rep("a", 60000) .. ".b"
local driver = { name = "pattern_literal_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.find(s, literal)
end
return driver
