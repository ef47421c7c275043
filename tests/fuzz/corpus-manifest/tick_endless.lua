return { name = "m", version = "1", tick = function() while true do end end }
