-- One passing test and one failing expectation with a known line.
test("adds", function()
	expect_eq(1 + 1, 2, "one plus one")
end)
test("adds wrongly", function()
	expect_eq(1 + 1, 3, "one plus one")
end)
