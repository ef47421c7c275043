-- a backtracking pattern that takes hours in one C call
-- expect: pattern too costly
local driver = { name = "pattern_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.find(string.rep('a', 5000), '.-.-.-.-b')
end
return driver
