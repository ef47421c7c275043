-- A test file that fails while it loads, before any test is declared.
local t = nil
test("never runs", function() end)
return t.field
