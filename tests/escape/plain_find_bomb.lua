-- find with plain = true: LuaJIT's naive search, 512 KiB compared at each of 512 K places (7.4 s in one C call)
-- expect: string\.find: plain search too costly
-- (the data is built at load, which has 50 times the budget: tick only makes the call)
local s = string.rep("a", 65536)
for _ = 1, 3 do
	s = s .. s
end
local needle = s .. "b"
s = s .. s
local driver = { name = "plain_find_bomb", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	s:find(needle, 1, true)
end
return driver
