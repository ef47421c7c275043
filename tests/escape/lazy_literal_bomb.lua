-- an anchored lazy .- then a 60,000-character literal, tried after every character taken (some 4.5 minutes)
-- expect: string\.match: pattern too costly
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("a", 65536)
for _ = 1, 4 do
	s = s .. s
end
local pattern = "^.-" .. string.rep("a", 60000) .. "b"
local driver = { name = "lazy_literal_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.match(s, pattern)
end
return driver
