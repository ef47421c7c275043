local io = {}
for i = 1, 40 do io["in" .. i] = "di" .. (i % 8) end
local vars = {}
for i = 1, 30 do vars["v" .. i] = {} end
return { name = "m", version = "1", io = io, variables = vars, tick = function() end }
