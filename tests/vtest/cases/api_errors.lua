-- Mistakes in the use of the test API: each is reported at the test's own
-- line, never at a line of the runner.
test("an unknown plant", function()
	board { name = "dryer-1", plant = "dryer" }
end)

test("an action that is not a name", function()
	local l = board { name = "lights-1", plant = "lights" }
	l:set(7, 1)
end)

test("an action the plant does not have", function()
	local l = board { name = "lights-1", plant = "lights" }
	l:press("doorbell")
end)

test("run_for without seconds", function()
	board { name = "lights-1", plant = "lights" }
	run_for("ten")
end)

test("an input value that is a table", function()
	local l = board { name = "lights-1", plant = "lights" }
	l:input("kitchen", { on = true })
end)

test("an unknown wire fault", function()
	local l = board { name = "lights-1", plant = "lights" }
	l:faults { lose = 0.1 }
end)

test("a grace that is not a time", function()
	always("anything", function() return true end, { within = "soon" })
end)

local function lights_with(params)
	return board { name = "lights-1", plant = "lights", params = params }
end

test("a mistake inside a helper of the test file", function()
	lights_with("on_minutes=5")
end)
