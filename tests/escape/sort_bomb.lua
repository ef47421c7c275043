-- table.sort of 8,000 references to two 512 KiB strings that differ in their last byte (4.5 s in one C call)
-- expect: table\.sort: too costly|time budget exceeded
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("a", 65536)
for _ = 1, 3 do
	s = s .. s
end
local a, b, t = s:sub(2) .. "a", s:sub(2) .. "b", {}
s = nil
for i = 1, 8000 do
	t[i] = i % 2 == 0 and a or b
end
local driver = { name = "sort_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	table.sort(t)
end
return driver
