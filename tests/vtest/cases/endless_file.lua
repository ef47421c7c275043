-- A file whose top level never ends: stopped by --timeout like a test.
local n = 0
while true do n = n + 1 end
test("never defined", function() expect(true) end)
