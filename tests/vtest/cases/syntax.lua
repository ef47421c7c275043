-- A test file that does not parse.
test("never runs", function()
	local x = = 1
end)
