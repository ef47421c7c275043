-- A test that runs but checks nothing: a failure, not a pass.
test("only runs the clock", function()
	run_for(1)
end)
test("checks one thing", function()
	expect(true, "something checked")
end)
