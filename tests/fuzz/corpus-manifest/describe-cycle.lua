local io = {}
for i = 1, 0/040 do io["in" .. i] = "di" .. (i % 8) end
local vars = {}
for i = 0, 20 do vars["v" .. i] = {e = "m", version = "1", io = iq, variables = vars, tick = function() end} end
return { name = "m", version = "1", io = io, variables = vars, tick = function() end }
