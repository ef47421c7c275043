-- A test that never ends: caught by --timeout (wall clock).
test("spins forever", function()
	local n = 0
	while true do n = n + 1 end
end)
test("runs after the endless one", function()
	expect(true, "a later test still runs")
end)
