-- memory creeping under pcall at the top of a file uploaded for hot reload (compiled on an HTTP thread)
-- expect: memory cap exceeded
-- trigger: upload
local G = {}
for i = 1, 1e7 do if not pcall(function() G[#G + 1] = { i } end) then break end end
return { name = "creep_upload", version = "1", io = { lamp = "do0" }, tick = function() end }
