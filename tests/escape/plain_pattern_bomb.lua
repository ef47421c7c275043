-- the same search without plain = true: a pattern with no special character is searched for as plain text (7 s)
-- expect: string\.find: plain search too costly
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("a", 65536)
for _ = 1, 3 do
	s = s .. s
end
local needle = s .. "b"
s = s .. s
local driver = { name = "plain_pattern_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	s:find(needle)
end
return driver
