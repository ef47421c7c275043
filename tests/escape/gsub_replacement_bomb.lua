-- gsub with an empty capture at each of 1 M places and a replacement that pushes it 30,000 times (some 7 minutes)
-- expect: string\.gsub: pattern too costly
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("y", 65536)
for _ = 1, 4 do
	s = s .. s
end
local replacement = string.rep("%1", 30000)
local driver = { name = "gsub_replacement_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.gsub(s, "(x?)", replacement)
end
return driver
