return { name = "m", version = "1", tick = function() end }
