-- gmatch takes a leading ^ as a character, not an anchor: one call of the iterator tries every place (8.6 s)
-- expect: string\.gmatch: pattern too costly
local s = string.rep("^", 2000)
local driver = { name = "gmatch_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	for _ in string.gmatch(s, "^.-.-b") do
	end
end
return driver
