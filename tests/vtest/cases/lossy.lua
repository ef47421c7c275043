-- Passes; its trace depends on the fault injector's seed (--seed).
test("lights over a lossy link", function()
	config { miss_limit = 1000 }
	local l = board { name = "lights-1", plant = "lights" }
	l:faults { drop = 0.2, delay = 0.0005, delay_fraction = 0.5 }
	run_until(function() return l.var.kitchen == false end, 5, "the lights attached")
	l:set("toggle1")
	run_until(function() return l.out.kitchen end, 2, "the kitchen light on")
	run_for(0.5)
end)
