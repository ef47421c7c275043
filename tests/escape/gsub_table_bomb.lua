-- gsub with an empty pattern and a table: a lookup from C at each of 1 M places (54 ms in one C call)
-- expect: string\.gsub: pattern too costly
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("y", 65536)
for _ = 1, 4 do
	s = s .. s
end
local driver = { name = "gsub_table_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	string.gsub(s, "", {})
end
return driver
