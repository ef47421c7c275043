local t = {}
local cur = t
for i = 1, 20 do cur.x = {} cur = cur.x end
return { name = "m", version = "1", ui = { deep = t, list = { 1, 2, nil, 4 }, f = print, mixed = { 1, a = 2 } }, tick = function() end }
