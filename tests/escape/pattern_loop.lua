-- a loop of library calls each within the cost model (a few ms of backtracking over 1.2 KiB), a thousand
-- of them between two budget hooks: each costly call looks at the wall clock first
-- expect: time budget exceeded
local s = string.rep("a", 1200)
local driver = { name = "pattern_loop", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	for _ = 1, 1000000 do
		s:find("a*b")
	end
end
return driver
