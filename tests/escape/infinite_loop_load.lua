-- an endless loop at the top of the file
-- expect: time budget exceeded
while true do end
return { name = "infinite_loop_load", version = "1", io = { lamp = "do0" }, tick = function(dev) dev.out.lamp = true end }
