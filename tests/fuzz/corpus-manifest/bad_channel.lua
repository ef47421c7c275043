return { name = "m", version = "1", io = { x = "do7", y = "ai2", z = "dx0", w = "di" }, tick = function() end }
