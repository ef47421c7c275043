-- An always() check that a driver's action breaks at a known moment.
test("the kitchen light stays off", function()
	local l = board { name = "lights-1", plant = "lights" }
	run_until(function() return l.var.kitchen == false end, 5, "the lights attached")
	always("the kitchen light stays off", function() return not l.out.kitchen end)
	l:input("kitchen", true)
	run_for(1)
end)
